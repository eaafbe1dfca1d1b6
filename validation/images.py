"""Image files for the harness: linear OpenEXR in and out (through Mitsuba's Bitmap), CS184's
tone step, PNGs and z-maps for the report."""
import numpy as np


def read_exr(path):
    import mitsuba as mi

    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def write_exr(path, img):
    import mitsuba as mi

    mi.Bitmap(np.asarray(img, dtype=np.float32)).write(path)


def to_png(img):
    """CS184's tone step, to compare images by eye."""
    return np.clip(np.power(np.maximum(img, 0) * np.sqrt(2.0), 1 / 2.2), 0, 1)


def write_png(path, rgb01):
    import mitsuba as mi

    mi.Bitmap((np.clip(rgb01, 0, 1) * 255).astype(np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB).write(path)


def write_zmap(path, z):
    """Blue (z <= -4) .. white (0) .. red (z >= 4), per pixel the worst channel."""
    zz = np.take_along_axis(z, np.argmax(np.abs(z), axis=-1)[..., None], -1)[..., 0]
    t = np.clip(zz / 4.0, -1, 1)
    write_png(path, np.stack([1 - np.clip(-t, 0, 1), 1 - np.abs(t), 1 - np.clip(t, 0, 1)], -1))
