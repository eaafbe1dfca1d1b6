/* A small, stable C API over Embree 3 and Embree 4, both in one process.
 *
 * shim.c is compiled once per Embree major, each time against that major's
 * headers. Each build loads its library at run time with dlopen(RTLD_LOCAL)
 * and calls it through a table of function pointers, so the two libraries,
 * which export the same rtc* names, never bind to each other's code; the
 * program itself links no Embree. Each build exports one function returning
 * its table: pt_embree3_api() and pt_embree4_api() (a build without a
 * major's headers does not define it; build.rs tells the Rust side which
 * exist).
 *
 * No Embree header is included here, so bindgen sees only these types.
 * Embree's structs (16- to 64-byte aligned, and larger in newer Embree 4
 * minors) stay on the C side.
 */
#ifndef PT_EMBREE_SHIM_H
#define PT_EMBREE_SHIM_H

#include <stddef.h>
#include <stdint.h>

#define PT_INVALID_ID 0xFFFFFFFFu

/* A ray: hits count for tnear < t <= tfar (our contract; see shim.c). */
typedef struct pt_ray {
    float org[3];
    float tnear;
    float dir[3];
    float tfar;
} pt_ray;

/* A hit; geom_id == PT_INVALID_ID on a miss. u, v weight vertices 1 and 2. */
typedef struct pt_hit {
    float t;
    float u;
    float v;
    uint32_t geom_id;
    uint32_t prim_id;
} pt_hit;

/* Sphere test supplied by the caller, so both backends compute the very same
 * t: returns the nearest t with tnear < t <= tfar, or a NaN for no hit. */
typedef float (*pt_sphere_fn)(const float center_radius[4], const float org[3], const float dir[3], float tnear, float tfar);

typedef struct pt_device pt_device;
typedef struct pt_scene pt_scene;

/* How a batch is handed to Embree: a loop of single-ray calls, Embree 3's
 * ray streams (rtcIntersect1M; Embree 4 has none), or packets of 4, 8 or 16. */
enum { PT_BATCH_LOOP = 0, PT_BATCH_STREAM = 1, PT_BATCH_PACKET8 = 2, PT_BATCH_PACKET4 = 3, PT_BATCH_PACKET16 = 4 };

/* One Embree major's entry points. Every function but load, library and
 * library_version needs a successful load() first. */
typedef struct pt_api {
    /* The major and RTC_VERSION of the headers this table was compiled
     * against (e.g. 4, 40200). */
    int major;
    int header_version;
    /* The library file(s) load() tries, for messages. */
    const char *library;
    /* Load the library (once; later calls return the first answer): NULL on
     * success, else why it cannot be used. */
    const char *(*load)(void);
    /* RTC_DEVICE_PROPERTY_VERSION of the loaded library (e.g. 40400). */
    int (*library_version)(void);

    /* NULL on failure; the message is then in device_new_error(). */
    pt_device *(*device_new)(const char *config);
    const char *(*device_new_error)(void);
    void (*device_release)(pt_device *d);
    /* The last error reported through Embree's error callback (0 if none),
     * and its message; reading clears it. */
    int (*device_take_error)(pt_device *d, char *msg, size_t msg_len);
    /* Bytes Embree currently has allocated on this device. */
    int64_t (*device_memory)(const pt_device *d);
    /* Whether this device supports the stream API (Embree 3 only). */
    int (*device_has_streams)(const pt_device *d);

    /* quality: 0 low, 1 medium, 2 high. */
    pt_scene *(*scene_new)(pt_device *d, int quality, int robust);
    /* 0 on success, -1 on error (see device_take_error). */
    int (*scene_add_mesh)(pt_scene *s, uint32_t geom_id, const float *xyz, size_t n_vertices, const uint32_t *tris, size_t n_tris);
    int (*scene_add_sphere)(pt_scene *s, uint32_t geom_id, const float center_radius[4], pt_sphere_fn test);
    int (*scene_commit)(pt_scene *s);
    void (*scene_release)(pt_scene *s);

    /* Thread-safe after a successful commit. Rays must be valid (finite,
     * non-zero direction, 0 <= tnear <= tfar): Embree's answer to others is
     * undefined. */
    void (*intersect1)(const pt_scene *s, const pt_ray *ray, pt_hit *hit);
    int (*occluded1)(const pt_scene *s, const pt_ray *ray);
    void (*intersect_batch)(const pt_scene *s, const pt_ray *rays, pt_hit *hits, size_t n, int mode, int coherent);
    void (*occluded_batch)(const pt_scene *s, const pt_ray *rays, uint8_t *occluded, size_t n, int mode, int coherent);

    /* The ABI canary: traces one ray at a one-triangle scene with a call of
     * `width` rays (1, 4, 8 or 16) whose hit structure is followed by bytes
     * set to a pattern, and returns how many of those bytes the library
     * wrote (the hit fields a newer library has and these headers lack), or
     * -1 on error. Every hit buffer has `abi_padding` such bytes. */
    int (*abi_probe)(int width);
    int abi_padding;
} pt_api;

const pt_api *pt_embree3_api(void);
const pt_api *pt_embree4_api(void);

#endif
