/* A small, stable C API over Embree 3 or 4.
 *
 * No Embree header is included here, so bindgen sees only these types and the
 * generated Rust bindings are the same whichever Embree version is installed.
 * Embree's structs (16-byte aligned, and larger in some Embree 4 builds) stay
 * on the C side.
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

/* Batch modes. */
enum { PT_BATCH_LOOP = 0, PT_BATCH_STREAM = 1, PT_BATCH_PACKET8 = 2 };

/* Version of the Embree headers the shim was compiled against, e.g. 31305. */
int pt_embree_version(void);

/* NULL on failure; the message is then in pt_device_new_error(). */
pt_device *pt_device_new(const char *config);
const char *pt_device_new_error(void);
void pt_device_release(pt_device *d);
/* The last error reported through Embree's error callback (0 if none), and
 * its message; reading clears it. */
int pt_device_take_error(pt_device *d, char *msg, size_t msg_len);
/* Bytes Embree currently has allocated on this device. */
int64_t pt_device_memory(const pt_device *d);
/* Whether this Embree build supports the stream API (Embree 3 only). */
int pt_device_has_streams(const pt_device *d);

/* quality: 0 low, 1 medium, 2 high. */
pt_scene *pt_scene_new(pt_device *d, int quality, int robust);
/* Returns 0 on success, -1 on error (see pt_device_take_error). */
int pt_scene_add_mesh(pt_scene *s, uint32_t geom_id, const float *xyz, size_t n_vertices, const uint32_t *tris, size_t n_tris);
int pt_scene_add_sphere(pt_scene *s, uint32_t geom_id, const float center_radius[4], pt_sphere_fn test);
int pt_scene_commit(pt_scene *s);
void pt_scene_release(pt_scene *s);

/* Thread-safe after a successful commit. Rays must be valid (finite, non-zero
 * direction, 0 <= tnear <= tfar): Embree's answer to others is undefined. */
void pt_intersect1(const pt_scene *s, const pt_ray *ray, pt_hit *hit);
int pt_occluded1(const pt_scene *s, const pt_ray *ray);
void pt_intersect_batch(const pt_scene *s, const pt_ray *rays, pt_hit *hits, size_t n, int mode, int coherent);
void pt_occluded_batch(const pt_scene *s, const pt_ray *rays, uint8_t *occluded, size_t n, int mode, int coherent);

#endif
