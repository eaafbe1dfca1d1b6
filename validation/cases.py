"""The harness's cases: what each tier renders, with which flags, against which references.
A case is a dict made by `radiance`, `geometry` or `adaptive`; run_cases.py runs them."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# Our renders per case: independent runs whose spread gives the variance of the mean.
BATCHES = 8


def radiance(scene, m, refs, flags=(), label=None, spp_scale=1, ref_shift=None, scene_flags=(), tag=""):
    """spp_scale multiplies our spp: hemisphere sampling finds a small light with few samples,
    and its per-pixel means are far from normal (most batches see 0-2 light hits) until there
    are many. scene_flags change the scene itself (-e environment map, -b/-d thin lens): they go
    to the export too, so the references render the same scene; tag names the case apart."""
    return {"kind": "radiance", "scene": scene, "m": m, "refs": refs, "flags": list(flags), "label": label, "spp_scale": spp_scale, "ref_shift": ref_shift,
            "scene_flags": list(scene_flags), "tag": tag}


def envmap(name):
    """An environment map from scenes/envmaps (CC0, see scenes/README.md); missing data stops the run."""
    p = os.path.join(ROOT, "scenes", "envmaps", name)
    if not os.path.exists(p):
        sys.exit(f"run_cases: environment map {p} not found (scenes/envmaps)")
    return os.path.abspath(p)


def geometry(scene, ref_shift=None):
    """The tag lets `--only _geometry` select the intersection cases alone."""
    return {"kind": "geometry", "scene": scene, "ref_shift": ref_shift, "tag": "_geometry"}


def adaptive(scene, m, refs, batch, tol, bias_runs):
    """Adaptive sampling (-a batch tol, at the tier's spp as the maximum): the converged image
    against the references, samples saved against uniform sampling at equal error, and the
    bias of CS184's stopping rule against the pilot variant over `bias_runs` short runs of a
    rare-path configuration (-H -m 1: a pixel whose first batch saw no light hit stops, dark)."""
    return {"kind": "adaptive", "scene": scene, "m": m, "refs": refs, "batch": batch, "tol": tol, "bias_runs": bias_runs, "ref_shift": None}


CB = "CBspheres_lambertian.dae"


BOTH = ["mitsuba", "cycles"]


ALL = BOTH + ["povray"]  # POV-Ray: direct lighting only


# Both light-path modes, named: `specular` is the default, `all` the other.
BDPT = ["--integrator", "bdpt", "--bdpt-light-paths", "all"]


BDPT_SPECULAR = ["--integrator", "bdpt", "--bdpt-light-paths", "specular"]


TIERS = {
    # width, height, our spp, reference spp per render, reference renders, spp ladder (error
    # against time) with independent renders per rung, cases
    "quick": dict(w=64, h=48, spp=256, ref_spp=128, ref_renders=16, ladder=[4, 16, 64], ladder_seeds=4, pov_supersample=4, pov_lightlets=8, cases=[
        radiance(CB, 1, ALL),
        radiance(CB, 1, ["cycles"], ["-H"], "hemisphere sampling", spp_scale=16),
        radiance(CB, 5, BOTH),
        radiance("CBempty.dae", 3, BOTH),
        radiance("hard_offset.dae", 3, BOTH, label="hard case: moved by 8192", ref_shift="normalise"),
        radiance("CBspheres.dae", 5, BOTH, label="mirror and glass"),
        radiance("bunny_unlit.dae", 3, BOTH, label="environment light (studio.exr)", scene_flags=["-e", envmap("studio.exr")], tag="_env_studio"),
        adaptive(CB, 5, ["cycles"], 32, 0.05, 12),
        geometry(CB),
        geometry("hard_tiny.dae"),
    ]),
    "full": dict(w=256, h=192, spp=1024, ref_spp=256, ref_renders=16, ladder=[4, 16, 64, 256], ladder_seeds=4, pov_supersample=2, pov_lightlets=16, cases=[
        radiance(CB, 1, ALL),
        radiance(CB, 1, BOTH, ["-H"], "hemisphere sampling", spp_scale=16),
        radiance(CB, 2, BOTH),
        radiance(CB, 5, BOTH),
        radiance("CBempty.dae", 1, ALL),
        radiance("CBempty.dae", 3, BOTH),
        radiance("CBbunny.dae", 5, BOTH),
        radiance("bunny.dae", 3, BOTH, label="hemisphere light"),
        adaptive(CB, 5, BOTH, 64, 0.05, 24),
        radiance("hard_offset.dae", 3, BOTH, label="hard case: moved by 8192", ref_shift="normalise"),
        radiance("hard_tiny.dae", 3, BOTH, label="hard case: scaled by 1e-3", ref_shift="normalise"),
        radiance("hard_huge.dae", 3, BOTH, label="hard case: scaled by 1e3", ref_shift="normalise"),
        radiance("hard_grazing.dae", 3, BOTH, label="hard case: light 1e-4 under the ceiling"),
        radiance("hard_slab.dae", 3, BOTH, label="hard case: 1e-4-thick slab"),
        radiance("CBspheres.dae", 5, BOTH, label="mirror and glass"),
        radiance("CBspheres_refract.dae", 5, BOTH, label="mirror and CS184 refraction"),
        radiance("CBgems.dae", 5, BOTH, label="tinted glass gems"),
        radiance("CBcoil.dae", 5, BOTH, label="mirror coil (reflectance 0.3)"),
        radiance("CBspheres_microfacet_al_ag.dae", 5, BOTH, label="microfacet Al and Ag"),
        radiance("CBbunny_microfacet_cu.dae", 5, BOTH, label="microfacet Cu"),
        radiance("bunny_unlit.dae", 3, BOTH, label="environment light (studio.exr)", scene_flags=["-e", envmap("studio.exr")], tag="_env_studio"),
        radiance("bunny_microfacet_cu_unlit.dae", 3, BOTH, label="microfacet Cu under courtyard.exr", scene_flags=["-e", envmap("courtyard.exr")], tag="_env_courtyard"),
        radiance(CB, 5, BOTH, label="thin lens -b 0.1 -d 4.5", scene_flags=["-b", "0.1", "-d", "4.5"], tag="_lens"),
        # Bidirectional path tracing (`--only _bdpt` runs these alone).
        radiance("CBspheres.dae", 5, BOTH, BDPT, label="BDPT: mirror and glass", tag="_bdpt"),
        radiance("CBspheres.dae", 8, BOTH, BDPT, label="BDPT: mirror and glass, -m 8", tag="_bdpt"),
        radiance("CBgems.dae", 5, BOTH, BDPT, label="BDPT: tinted glass gems", tag="_bdpt"),
        radiance("CBbunny.dae", 5, BOTH, BDPT, label="BDPT: diffuse bunny", tag="_bdpt"),
        # BDPT with only the light subpaths that start with a specular bounce
        # (`--only _specular_bdpt` runs these alone).
        radiance("CBspheres.dae", 5, BOTH, BDPT_SPECULAR, label="BDPT, specular light paths: mirror and glass", tag="_specular_bdpt"),
        radiance("CBspheres.dae", 8, BOTH, BDPT_SPECULAR, label="BDPT, specular light paths: mirror and glass, -m 8", tag="_specular_bdpt"),
        radiance("CBgems.dae", 5, BOTH, BDPT_SPECULAR, label="BDPT, specular light paths: tinted glass gems", tag="_specular_bdpt"),
        radiance("CBbunny.dae", 5, BOTH, BDPT_SPECULAR, label="BDPT, specular light paths: diffuse bunny", tag="_specular_bdpt"),
        radiance(CB, 5, BOTH, BDPT, label="BDPT: thin lens -b 0.1 -d 4.5", scene_flags=["-b", "0.1", "-d", "4.5"], tag="_lens_bdpt"),
        radiance("bunny_unlit.dae", 3, BOTH, BDPT, label="BDPT: environment light (studio.exr)", scene_flags=["-e", envmap("studio.exr")], tag="_env_bdpt"),
        radiance(CB, 5, BOTH + ["mitsuba_ptracer"], ["--integrator", "light"], label="light tracing (diffuse: it cannot see mirrors and glass)", tag="_light_bdpt"),
        geometry(CB),
        geometry("CBbunny.dae"),
        geometry("hard_offset.dae", ref_shift="normalise"),
        geometry("hard_tiny.dae", ref_shift="normalise"),
        geometry("hard_huge.dae", ref_shift="normalise"),
        geometry("hard_slab.dae"),
        geometry("hard_grazing.dae"),
    ]),
}


def own_scene_cases(path, m, refs, scene_flags=()):
    """The cases for a user's own scene (`validation/run TIER --scene FILE`): its radiance at
    -m m against the chosen references, and its intersections (object ids, distances, normals)
    against POV-Ray and Cycles."""
    if not os.path.exists(path):
        sys.exit(f"run_cases: scene {path} not found")
    path = os.path.abspath(path)
    return [radiance(path, m, refs, label=f"your scene at -m {m}", scene_flags=scene_flags), geometry(path)]


def find_scene(name):
    if os.path.isabs(name) and os.path.exists(name):
        return name
    for d in [os.path.join(ROOT, "scenes", "cs184", "sky"), os.path.join(HERE, "scenes")]:
        p = os.path.join(d, name)
        if os.path.exists(p):
            return p
    sys.exit(f"run_cases: scene {name} not found (looked in scenes/cs184/sky and validation/scenes)")
