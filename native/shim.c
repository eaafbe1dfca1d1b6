/* The Embree shim: one source for Embree 3 and 4 (see shim.h).
 *
 * Range convention. Our contract counts hits with tnear < t <= tfar; Embree
 * counts tnear <= t <= tfar. Floats are discrete, so passing Embree the next
 * float above tnear gives exactly our half-open range.
 */
#include "shim.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if PT_EMBREE_MAJOR == 4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif

#if RTC_VERSION_MAJOR >= 4
#define PT_CTX_DECL(coh)                                                  \
    RTCIntersectArguments iargs;                                          \
    rtcInitIntersectArguments(&iargs);                                    \
    iargs.flags = (coh) ? RTC_RAY_QUERY_FLAG_COHERENT : RTC_RAY_QUERY_FLAG_INCOHERENT; \
    RTCOccludedArguments oargs;                                           \
    rtcInitOccludedArguments(&oargs);                                     \
    oargs.flags = iargs.flags;
#define PT_INTERSECT1(s, rh) rtcIntersect1((s), (rh), &iargs)
#define PT_OCCLUDED1(s, r) rtcOccluded1((s), (r), &oargs)
#define PT_INTERSECT8(v, s, rh) rtcIntersect8((v), (s), (rh), &iargs)
#define PT_OCCLUDED8(v, s, r) rtcOccluded8((v), (s), (r), &oargs)
#else
#define PT_CTX_DECL(coh)                                                  \
    struct RTCIntersectContext ctx;                                       \
    rtcInitIntersectContext(&ctx);                                        \
    ctx.flags = (coh) ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
#define PT_INTERSECT1(s, rh) rtcIntersect1((s), &ctx, (rh))
#define PT_OCCLUDED1(s, r) rtcOccluded1((s), &ctx, (r))
#define PT_INTERSECT8(v, s, rh) rtcIntersect8((v), (s), &ctx, (rh))
#define PT_OCCLUDED8(v, s, r) rtcOccluded8((v), (s), &ctx, (r))
#endif

struct pt_device {
    RTCDevice dev;
    atomic_llong bytes;
    int error;
    char message[512];
};

struct pt_scene {
    pt_device *d;
    RTCScene scene;
    /* User data of the sphere geometries, freed with the scene. */
    void **owned;
    size_t n_owned, cap_owned;
};

typedef struct {
    float cr[4];
    pt_sphere_fn test;
} sphere_data;

static char new_error[512];

int pt_embree_version(void) { return RTC_VERSION; }

static void on_error(void *user, enum RTCError code, const char *str) {
    pt_device *d = (pt_device *)user;
    if (d->error == 0) {
        d->error = (int)code;
        snprintf(d->message, sizeof d->message, "%s", str ? str : "unknown Embree error");
    }
}

static bool on_memory(void *user, ssize_t bytes, bool post) {
    (void)post;
    pt_device *d = (pt_device *)user;
    atomic_fetch_add(&d->bytes, (long long)bytes);
    return true;
}

pt_device *pt_device_new(const char *config) {
    pt_device *d = (pt_device *)calloc(1, sizeof *d);
    if (!d) {
        snprintf(new_error, sizeof new_error, "out of memory");
        return NULL;
    }
    d->dev = rtcNewDevice(config);
    if (!d->dev) {
        snprintf(new_error, sizeof new_error, "rtcNewDevice(\"%s\") failed (error %d)", config ? config : "", (int)rtcGetDeviceError(NULL));
        free(d);
        return NULL;
    }
    atomic_init(&d->bytes, 0);
    rtcSetDeviceErrorFunction(d->dev, on_error, d);
    rtcSetDeviceMemoryMonitorFunction(d->dev, on_memory, d);
    return d;
}

const char *pt_device_new_error(void) { return new_error; }

void pt_device_release(pt_device *d) {
    if (!d) return;
    rtcReleaseDevice(d->dev);
    free(d);
}

int pt_device_take_error(pt_device *d, char *msg, size_t msg_len) {
    int e = d->error;
    if (msg && msg_len) snprintf(msg, msg_len, "%s", e ? d->message : "");
    d->error = 0;
    d->message[0] = 0;
    return e;
}

int64_t pt_device_memory(const pt_device *d) { return (int64_t)atomic_load(&((pt_device *)d)->bytes); }

int pt_device_has_streams(const pt_device *d) {
#if RTC_VERSION_MAJOR >= 4
    (void)d;
    return 0;
#else
    return (int)rtcGetDeviceProperty(d->dev, RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED);
#endif
}

pt_scene *pt_scene_new(pt_device *d, int quality, int robust) {
    pt_scene *s = (pt_scene *)calloc(1, sizeof *s);
    if (!s) return NULL;
    s->d = d;
    s->scene = rtcNewScene(d->dev);
    if (!s->scene) {
        free(s);
        return NULL;
    }
    rtcSetSceneBuildQuality(s->scene, quality == 0 ? RTC_BUILD_QUALITY_LOW : quality == 2 ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
    rtcSetSceneFlags(s->scene, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    return s;
}

int pt_scene_add_mesh(pt_scene *s, uint32_t geom_id, const float *xyz, size_t n_vertices, const uint32_t *tris, size_t n_tris) {
    RTCGeometry g = rtcNewGeometry(s->d->dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!g) return -1;
    float *v = (float *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), n_vertices);
    unsigned *ix = (unsigned *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), n_tris);
    if (!v || !ix) {
        rtcReleaseGeometry(g);
        return -1;
    }
    memcpy(v, xyz, n_vertices * 3 * sizeof(float));
    memcpy(ix, tris, n_tris * 3 * sizeof(unsigned));
    rtcSetGeometryMask(g, 0xFFFFFFFFu);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(s->scene, g, geom_id);
    rtcReleaseGeometry(g);
    return s->d->error ? -1 : 0;
}

/* SoA accessors for N-wide rays and hits: Embree's own RTCRayN_* helpers
 * exist only in C++; this is the same layout (rtcore_ray.h). */
#define PT_RAYN_F(ray, N, i, field) (((float *)(ray))[(field) * (N) + (i)])
#define PT_HITN_F(hit, N, i, field) (((float *)(hit))[(field) * (N) + (i)])
#define PT_HITN_U(hit, N, i, field) (((unsigned *)(hit))[(field) * (N) + (i)])
enum { R_ORG_X = 0, R_ORG_Y, R_ORG_Z, R_TNEAR, R_DIR_X, R_DIR_Y, R_DIR_Z, R_TIME, R_TFAR };
enum { H_NG_X = 0, H_NG_Y, H_NG_Z, H_U, H_V, H_PRIM, H_GEOM, H_INST0 };

/* User-geometry callbacks for spheres: they call the caller's sphere test so
 * t is bit-identical to the native backend's (Embree's own sphere primitive
 * computes t differently). */
static void sphere_bounds(const struct RTCBoundsFunctionArguments *args) {
    const sphere_data *sd = (const sphere_data *)args->geometryUserPtr;
    const float *c = sd->cr;
    args->bounds_o->lower_x = c[0] - c[3];
    args->bounds_o->lower_y = c[1] - c[3];
    args->bounds_o->lower_z = c[2] - c[3];
    args->bounds_o->upper_x = c[0] + c[3];
    args->bounds_o->upper_y = c[1] + c[3];
    args->bounds_o->upper_z = c[2] + c[3];
}

/* nextafterf(x, INFINITY) and, for x > 0, nextafterf(x, 0), inline: libm's
 * out-of-line call, one per ray, was 0.7 % of an Embree render's profile
 * (CBgems; the render time moved within noise). Same bits as libm's on every
 * 997th float pattern and the special values (checked when written). */
static inline float next_up(float x) {
    if (x != x || x == INFINITY) return x;
    if (x == 0.0f) return 1.40129846e-45f; /* from +0 or -0: the smallest denormal */
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    b = x > 0.0f ? b + 1 : b - 1;
    memcpy(&x, &b, sizeof x);
    return x;
}

static inline float next_down_positive(float x) {
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    b -= 1;
    memcpy(&x, &b, sizeof x);
    return x;
}

/* Embree passes tnear as the next float above ours (see the top of the file):
 * undo that so the test sees our range. */
static float our_tnear(float embree_tnear) { return embree_tnear > 0.0f ? next_down_positive(embree_tnear) : embree_tnear; }

static void sphere_intersect(const struct RTCIntersectFunctionNArguments *args) {
    const sphere_data *sd = (const sphere_data *)args->geometryUserPtr;
    unsigned N = args->N;
    float *ray = (float *)args->rayhit;
    float *hit = ray + 12 * N;
    for (unsigned i = 0; i < N; i++) {
        if (!args->valid[i]) continue;
        float org[3] = {PT_RAYN_F(ray, N, i, R_ORG_X), PT_RAYN_F(ray, N, i, R_ORG_Y), PT_RAYN_F(ray, N, i, R_ORG_Z)};
        float dir[3] = {PT_RAYN_F(ray, N, i, R_DIR_X), PT_RAYN_F(ray, N, i, R_DIR_Y), PT_RAYN_F(ray, N, i, R_DIR_Z)};
        float tnear = our_tnear(PT_RAYN_F(ray, N, i, R_TNEAR));
        float t = sd->test(sd->cr, org, dir, tnear, PT_RAYN_F(ray, N, i, R_TFAR));
        if (!(t == t)) continue;
        PT_RAYN_F(ray, N, i, R_TFAR) = t;
        PT_HITN_F(hit, N, i, H_NG_X) = org[0] + t * dir[0] - sd->cr[0];
        PT_HITN_F(hit, N, i, H_NG_Y) = org[1] + t * dir[1] - sd->cr[1];
        PT_HITN_F(hit, N, i, H_NG_Z) = org[2] + t * dir[2] - sd->cr[2];
        PT_HITN_F(hit, N, i, H_U) = 0.0f;
        PT_HITN_F(hit, N, i, H_V) = 0.0f;
        PT_HITN_U(hit, N, i, H_PRIM) = args->primID;
        PT_HITN_U(hit, N, i, H_GEOM) = args->geomID;
        PT_HITN_U(hit, N, i, H_INST0) = args->context->instID[0];
    }
}

static void sphere_occluded(const struct RTCOccludedFunctionNArguments *args) {
    const sphere_data *sd = (const sphere_data *)args->geometryUserPtr;
    unsigned N = args->N;
    float *ray = (float *)args->ray;
    for (unsigned i = 0; i < N; i++) {
        if (!args->valid[i]) continue;
        float org[3] = {PT_RAYN_F(ray, N, i, R_ORG_X), PT_RAYN_F(ray, N, i, R_ORG_Y), PT_RAYN_F(ray, N, i, R_ORG_Z)};
        float dir[3] = {PT_RAYN_F(ray, N, i, R_DIR_X), PT_RAYN_F(ray, N, i, R_DIR_Y), PT_RAYN_F(ray, N, i, R_DIR_Z)};
        float tnear = our_tnear(PT_RAYN_F(ray, N, i, R_TNEAR));
        float t = sd->test(sd->cr, org, dir, tnear, PT_RAYN_F(ray, N, i, R_TFAR));
        if (t == t) PT_RAYN_F(ray, N, i, R_TFAR) = -INFINITY;
    }
}

int pt_scene_add_sphere(pt_scene *s, uint32_t geom_id, const float center_radius[4], pt_sphere_fn test) {
    RTCGeometry g = rtcNewGeometry(s->d->dev, RTC_GEOMETRY_TYPE_USER);
    if (!g) return -1;
    sphere_data *sd = (sphere_data *)malloc(sizeof *sd);
    if (!sd) {
        rtcReleaseGeometry(g);
        return -1;
    }
    memcpy(sd->cr, center_radius, sizeof sd->cr);
    sd->test = test;
    rtcSetGeometryUserPrimitiveCount(g, 1);
    rtcSetGeometryUserData(g, sd);
    rtcSetGeometryBoundsFunction(g, sphere_bounds, NULL);
    rtcSetGeometryIntersectFunction(g, sphere_intersect);
    rtcSetGeometryOccludedFunction(g, sphere_occluded);
    rtcSetGeometryMask(g, 0xFFFFFFFFu);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(s->scene, g, geom_id);
    /* The scene holds the geometry; free the user data with the scene. */
    rtcReleaseGeometry(g);
    if (s->n_owned == s->cap_owned) {
        size_t cap = s->cap_owned ? 2 * s->cap_owned : 8;
        void **grown = (void **)realloc(s->owned, cap * sizeof *grown);
        if (!grown) {
            free(sd);
            return -1;
        }
        s->owned = grown;
        s->cap_owned = cap;
    }
    s->owned[s->n_owned++] = sd;
    return s->d->error ? -1 : 0;
}

int pt_scene_commit(pt_scene *s) {
    rtcCommitScene(s->scene);
    return s->d->error ? -1 : 0;
}

void pt_scene_release(pt_scene *s) {
    if (!s) return;
    rtcReleaseScene(s->scene);
    for (size_t i = 0; i < s->n_owned; i++) free(s->owned[i]);
    free(s->owned);
    free(s);
}

static void to_rayhit(const pt_ray *r, struct RTCRayHit *rh) {
    rh->ray.org_x = r->org[0];
    rh->ray.org_y = r->org[1];
    rh->ray.org_z = r->org[2];
    rh->ray.tnear = next_up(r->tnear);
    rh->ray.dir_x = r->dir[0];
    rh->ray.dir_y = r->dir[1];
    rh->ray.dir_z = r->dir[2];
    rh->ray.time = 0.0f;
    rh->ray.tfar = r->tfar;
    rh->ray.mask = 0xFFFFFFFFu;
    rh->ray.id = 0;
    rh->ray.flags = 0;
    rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh->hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

static void from_rayhit(const struct RTCRayHit *rh, pt_hit *h) {
    h->geom_id = rh->hit.geomID;
    h->prim_id = rh->hit.primID;
    h->t = rh->ray.tfar;
    h->u = rh->hit.u;
    h->v = rh->hit.v;
}

void pt_intersect1(const pt_scene *s, const pt_ray *ray, pt_hit *hit) {
    PT_CTX_DECL(0);
    struct RTCRayHit rh;
    to_rayhit(ray, &rh);
    PT_INTERSECT1(s->scene, &rh);
    from_rayhit(&rh, hit);
}

int pt_occluded1(const pt_scene *s, const pt_ray *ray) {
    PT_CTX_DECL(0);
    struct RTCRayHit rh;
    to_rayhit(ray, &rh);
    PT_OCCLUDED1(s->scene, &rh.ray);
    return rh.ray.tfar == -INFINITY;
}

static void load8(struct RTCRayHit8 *p, int *valid, const pt_ray *rays, size_t n) {
    for (size_t k = 0; k < 8; k++) {
        if (k >= n) {
            valid[k] = 0;
            p->ray.tnear[k] = 0.0f;
            p->ray.tfar[k] = -INFINITY;
            continue;
        }
        const pt_ray *r = &rays[k];
        valid[k] = -1;
        p->ray.org_x[k] = r->org[0];
        p->ray.org_y[k] = r->org[1];
        p->ray.org_z[k] = r->org[2];
        p->ray.dir_x[k] = r->dir[0];
        p->ray.dir_y[k] = r->dir[1];
        p->ray.dir_z[k] = r->dir[2];
        p->ray.tnear[k] = next_up(r->tnear);
        p->ray.tfar[k] = r->tfar;
        p->ray.time[k] = 0.0f;
        p->ray.mask[k] = 0xFFFFFFFFu;
        p->ray.id[k] = (unsigned)k;
        p->ray.flags[k] = 0;
        p->hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        p->hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
        p->hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
}

void pt_intersect_batch(const pt_scene *s, const pt_ray *rays, pt_hit *hits, size_t n, int mode, int coherent) {
    PT_CTX_DECL(coherent);
    if (mode == PT_BATCH_PACKET8) {
        for (size_t i = 0; i < n; i += 8) {
            RTC_ALIGN(32) int valid[8];
            RTC_ALIGN(32) struct RTCRayHit8 p;
            size_t m = n - i < 8 ? n - i : 8;
            load8(&p, valid, rays + i, m);
            PT_INTERSECT8(valid, s->scene, &p);
            for (size_t k = 0; k < m; k++) {
                hits[i + k].geom_id = p.hit.geomID[k];
                hits[i + k].prim_id = p.hit.primID[k];
                hits[i + k].t = p.ray.tfar[k];
                hits[i + k].u = p.hit.u[k];
                hits[i + k].v = p.hit.v[k];
            }
        }
        return;
    }
#if RTC_VERSION_MAJOR < 4
    if (mode == PT_BATCH_STREAM) {
        enum { CHUNK = 256 };
        struct RTCRayHit buf[CHUNK];
        for (size_t i = 0; i < n; i += CHUNK) {
            size_t m = n - i < CHUNK ? n - i : CHUNK;
            for (size_t k = 0; k < m; k++) to_rayhit(&rays[i + k], &buf[k]);
            rtcIntersect1M(s->scene, &ctx, buf, (unsigned)m, sizeof(struct RTCRayHit));
            for (size_t k = 0; k < m; k++) from_rayhit(&buf[k], &hits[i + k]);
        }
        return;
    }
#endif
    for (size_t i = 0; i < n; i++) {
        struct RTCRayHit rh;
        to_rayhit(&rays[i], &rh);
        PT_INTERSECT1(s->scene, &rh);
        from_rayhit(&rh, &hits[i]);
    }
}

void pt_occluded_batch(const pt_scene *s, const pt_ray *rays, uint8_t *occluded, size_t n, int mode, int coherent) {
    PT_CTX_DECL(coherent);
    if (mode == PT_BATCH_PACKET8) {
        for (size_t i = 0; i < n; i += 8) {
            RTC_ALIGN(32) int valid[8];
            RTC_ALIGN(32) struct RTCRayHit8 p;
            size_t m = n - i < 8 ? n - i : 8;
            load8(&p, valid, rays + i, m);
            PT_OCCLUDED8(valid, s->scene, &p.ray);
            for (size_t k = 0; k < m; k++) occluded[i + k] = p.ray.tfar[k] == -INFINITY;
        }
        return;
    }
#if RTC_VERSION_MAJOR < 4
    if (mode == PT_BATCH_STREAM) {
        enum { CHUNK = 256 };
        struct RTCRayHit buf[CHUNK];
        for (size_t i = 0; i < n; i += CHUNK) {
            size_t m = n - i < CHUNK ? n - i : CHUNK;
            for (size_t k = 0; k < m; k++) to_rayhit(&rays[i + k], &buf[k]);
            rtcOccluded1M(s->scene, &ctx, (struct RTCRay *)buf, (unsigned)m, sizeof(struct RTCRayHit));
            for (size_t k = 0; k < m; k++) occluded[i + k] = buf[k].ray.tfar == -INFINITY;
        }
        return;
    }
#endif
    for (size_t i = 0; i < n; i++) occluded[i] = (uint8_t)pt_occluded1(s, &rays[i]);
}
