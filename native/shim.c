/* The Embree shim: one source, compiled once per Embree major (see shim.h).
 *
 * Build flags (build.rs): PT_EMBREE_MAJOR (3 or 4), PT_API_FN (the exported
 * table's getter, pt_embree3_api or pt_embree4_api) and PT_EMBREE_LIBS (the
 * library files to try, colon-separated, absolute paths first).
 *
 * Loading. The library is opened with dlopen(RTLD_NOW | RTLD_LOCAL) and
 * every rtc* function the shim calls is looked up into `rtc`, a table of
 * pointers typed from this major's headers. Nothing here links Embree, so
 * Embree 3 and Embree 4, which export the same names, live side by side,
 * each resolving its own symbols.
 *
 * ABI. The headers may be older than the library (embree4-sys carries
 * 4.2.0's; the wheel is 4.4.0, built with instance arrays: its hits end with
 * an instPrimID field that 4.2's lack, and it writes it). Embree documents no
 * ABI promise across 4.x minors, so every hit buffer and every argument
 * structure handed to Embree 4 is followed by PT_PAD zeroed bytes it may
 * write or read, and abi_probe measures what it writes (a test keeps it
 * within the padding). Only fields present in every version are read back.
 *
 * Range convention. Our contract counts hits with tnear < t <= tfar; Embree
 * counts tnear <= t <= tfar. Floats are discrete, so passing Embree the next
 * float above tnear gives exactly our half-open range.
 */
#include "shim.h"

#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if PT_EMBREE_MAJOR == 4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif

#if !defined(PT_API_FN) || !defined(PT_EMBREE_LIBS)
#error "build.rs defines PT_API_FN and PT_EMBREE_LIBS"
#endif
#if RTC_VERSION_MAJOR != PT_EMBREE_MAJOR
#error "PT_EMBREE_MAJOR does not match the headers found"
#endif

/* Bytes after every structure handed to the library (see the top). */
#if RTC_VERSION_MAJOR >= 4
#define PT_PAD 1024
#else
#define PT_PAD 64
#endif

/* ------------------------------------------------------------------ loading */

#if RTC_VERSION_MAJOR >= 4
#define PT_STREAM_FUNCS(X)
#else
#define PT_STREAM_FUNCS(X) X(rtcIntersect1M) X(rtcOccluded1M)
#endif
#define PT_RTC_FUNCS(X)                                                                                    \
    X(rtcNewDevice) X(rtcGetDeviceError) X(rtcReleaseDevice) X(rtcSetDeviceErrorFunction)                  \
    X(rtcSetDeviceMemoryMonitorFunction) X(rtcGetDeviceProperty) X(rtcNewScene) X(rtcSetSceneBuildQuality) \
    X(rtcSetSceneFlags) X(rtcNewGeometry) X(rtcSetNewGeometryBuffer) X(rtcSetGeometryMask)                  \
    X(rtcCommitGeometry) X(rtcAttachGeometryByID) X(rtcReleaseGeometry) X(rtcSetGeometryUserPrimitiveCount) \
    X(rtcSetGeometryUserData) X(rtcSetGeometryBoundsFunction) X(rtcSetGeometryIntersectFunction)           \
    X(rtcSetGeometryOccludedFunction) X(rtcCommitScene) X(rtcReleaseScene) X(rtcIntersect1) X(rtcOccluded1) \
    X(rtcIntersect4) X(rtcOccluded4) X(rtcIntersect8) X(rtcOccluded8) X(rtcIntersect16) X(rtcOccluded16)    \
    PT_STREAM_FUNCS(X)

static struct {
#define PT_FIELD(f) __typeof__(&f) f;
    PT_RTC_FUNCS(PT_FIELD)
#undef PT_FIELD
} rtc;

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static const char *load_result = "not loaded";
static char load_message[1024];
static int lib_version;

static void do_load(void) {
    char libs[1024];
    snprintf(libs, sizeof libs, "%s", PT_EMBREE_LIBS);
    void *h = NULL;
    char tried[1024] = "";
    for (char *save = NULL, *name = strtok_r(libs, ":", &save); name && !h; name = strtok_r(NULL, ":", &save)) {
        h = dlopen(name, RTLD_NOW | RTLD_LOCAL);
        if (!h) {
            const char *why = dlerror();
            snprintf(tried + strlen(tried), sizeof tried - strlen(tried), "%s%s", tried[0] ? "; " : "", why ? why : name);
        }
    }
    if (!h) {
        snprintf(load_message, sizeof load_message, "cannot load the Embree %d library (%s)", RTC_VERSION_MAJOR, tried);
        load_result = load_message;
        return;
    }
#define PT_LOOKUP(f)                                                                                         \
    rtc.f = (__typeof__(rtc.f))dlsym(h, #f);                                                                 \
    if (!rtc.f) {                                                                                            \
        snprintf(load_message, sizeof load_message, "the Embree %d library has no %s", RTC_VERSION_MAJOR, #f); \
        load_result = load_message;                                                                          \
        return;                                                                                              \
    }
    PT_RTC_FUNCS(PT_LOOKUP)
#undef PT_LOOKUP
    RTCDevice d = rtc.rtcNewDevice(NULL);
    if (!d) {
        snprintf(load_message, sizeof load_message, "the Embree %d library loaded, but rtcNewDevice failed (error %d)", RTC_VERSION_MAJOR,
                 (int)rtc.rtcGetDeviceError(NULL));
        load_result = load_message;
        return;
    }
    lib_version = (int)rtc.rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_VERSION);
    rtc.rtcReleaseDevice(d);
    if (lib_version / 10000 != RTC_VERSION_MAJOR) {
        snprintf(load_message, sizeof load_message, "the library is Embree %d.%d.%d, not the Embree %d the headers describe", lib_version / 10000,
                 (lib_version / 100) % 100, lib_version % 100, RTC_VERSION_MAJOR);
        load_result = load_message;
        return;
    }
    load_result = NULL;
}

static const char *load(void) {
    pthread_once(&load_once, do_load);
    return load_result;
}

static int library_version(void) { return load() ? 0 : lib_version; }

/* ------------------------------------------------------------ query set-up */

typedef struct {
#if RTC_VERSION_MAJOR >= 4
    struct RTCIntersectArguments i;
    unsigned char pad_i[PT_PAD];
    struct RTCOccludedArguments o;
    unsigned char pad_o[PT_PAD];
#else
    struct RTCIntersectContext ctx;
    unsigned char pad[PT_PAD];
#endif
} query;

/* Zeroed (padding included), then Embree's own initialiser. The coherent
 * flag is what Embree 4 has in place of streams: it tells the traversal the
 * rays of a call go roughly the same way. */
static void query_init(query *q, int coherent) {
    memset(q, 0, sizeof *q);
#if RTC_VERSION_MAJOR >= 4
    rtcInitIntersectArguments(&q->i);
    rtcInitOccludedArguments(&q->o);
    q->i.flags = coherent ? RTC_RAY_QUERY_FLAG_COHERENT : RTC_RAY_QUERY_FLAG_INCOHERENT;
    q->o.flags = q->i.flags;
#else
    rtcInitIntersectContext(&q->ctx);
    q->ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
#endif
}

/* This thread's set-up query of each kind (coherent or not), made once:
 * zeroing a query's padding is ~2 KB of stores, which made every
 * one-ray call of Embree 4 about 30 % slower when each call made its own
 * (rtcIntersect1 loop on cow's random rays: 3.9 against 5.8 Mrays/s).
 * Embree only reads a query; a thread's own copy keeps even Embree 3's
 * context, which its instance traversal may write, unshared. */
static query *query_of(int coherent) {
    static _Thread_local query made[2];
    static _Thread_local bool ready[2];
    int k = coherent ? 1 : 0;
    if (!ready[k]) {
        query_init(&made[k], coherent);
        ready[k] = true;
    }
    return &made[k];
}

#if RTC_VERSION_MAJOR >= 4
#define ISECT1(q, s, rh) rtc.rtcIntersect1((s), (rh), &(q)->i)
#define OCC1(q, s, r) rtc.rtcOccluded1((s), (r), &(q)->o)
#define ISECTN(n, q, v, s, rh) rtc.rtcIntersect##n((v), (s), (struct RTCRayHit##n *)(rh), &(q)->i)
#define OCCN(n, q, v, s, r) rtc.rtcOccluded##n((v), (s), (struct RTCRay##n *)(r), &(q)->o)
#else
#define ISECT1(q, s, rh) rtc.rtcIntersect1((s), &(q)->ctx, (rh))
#define OCC1(q, s, r) rtc.rtcOccluded1((s), &(q)->ctx, (r))
#define ISECTN(n, q, v, s, rh) rtc.rtcIntersect##n((v), (s), &(q)->ctx, (struct RTCRayHit##n *)(rh))
#define OCCN(n, q, v, s, r) rtc.rtcOccluded##n((v), (s), &(q)->ctx, (struct RTCRay##n *)(r))
#endif

/* One ray's hit record, followed by the bytes a newer library may write. */
typedef struct {
    struct RTCRayHit v;
    unsigned char pad[PT_PAD];
} rayhit1;

/* A packet of up to 16 rays, in the largest packet's space. */
typedef struct {
    RTC_ALIGN(64) unsigned char bytes[sizeof(struct RTCRayHit16) + PT_PAD];
} packet;

/* ------------------------------------------------------------------ devices */

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

static pt_device *device_new(const char *config) {
    const char *why = load();
    if (why) {
        snprintf(new_error, sizeof new_error, "%s", why);
        return NULL;
    }
    pt_device *d = (pt_device *)calloc(1, sizeof *d);
    if (!d) {
        snprintf(new_error, sizeof new_error, "out of memory");
        return NULL;
    }
    d->dev = rtc.rtcNewDevice(config);
    if (!d->dev) {
        snprintf(new_error, sizeof new_error, "rtcNewDevice(\"%s\") failed (error %d)", config ? config : "", (int)rtc.rtcGetDeviceError(NULL));
        free(d);
        return NULL;
    }
    atomic_init(&d->bytes, 0);
    rtc.rtcSetDeviceErrorFunction(d->dev, on_error, d);
    rtc.rtcSetDeviceMemoryMonitorFunction(d->dev, on_memory, d);
    return d;
}

static const char *device_new_error(void) { return new_error; }

static void device_release(pt_device *d) {
    if (!d) return;
    rtc.rtcReleaseDevice(d->dev);
    free(d);
}

static int device_take_error(pt_device *d, char *msg, size_t msg_len) {
    int e = d->error;
    if (msg && msg_len) snprintf(msg, msg_len, "%s", e ? d->message : "");
    d->error = 0;
    d->message[0] = 0;
    return e;
}

static int64_t device_memory(const pt_device *d) { return (int64_t)atomic_load(&((pt_device *)d)->bytes); }

static int device_has_streams(const pt_device *d) {
#if RTC_VERSION_MAJOR >= 4
    (void)d;
    return 0;
#else
    return (int)rtc.rtcGetDeviceProperty(d->dev, RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED);
#endif
}

/* ------------------------------------------------------------------- scenes */

static pt_scene *scene_new(pt_device *d, int quality, int robust) {
    pt_scene *s = (pt_scene *)calloc(1, sizeof *s);
    if (!s) return NULL;
    s->d = d;
    s->scene = rtc.rtcNewScene(d->dev);
    if (!s->scene) {
        free(s);
        return NULL;
    }
    rtc.rtcSetSceneBuildQuality(s->scene, quality == 0 ? RTC_BUILD_QUALITY_LOW : quality == 2 ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
    rtc.rtcSetSceneFlags(s->scene, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    return s;
}

static int scene_add_mesh(pt_scene *s, uint32_t geom_id, const float *xyz, size_t n_vertices, const uint32_t *tris, size_t n_tris) {
    RTCGeometry g = rtc.rtcNewGeometry(s->d->dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!g) return -1;
    float *v = (float *)rtc.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), n_vertices);
    unsigned *ix = (unsigned *)rtc.rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), n_tris);
    if (!v || !ix) {
        rtc.rtcReleaseGeometry(g);
        return -1;
    }
    memcpy(v, xyz, n_vertices * 3 * sizeof(float));
    memcpy(ix, tris, n_tris * 3 * sizeof(unsigned));
    rtc.rtcSetGeometryMask(g, 0xFFFFFFFFu);
    rtc.rtcCommitGeometry(g);
    rtc.rtcAttachGeometryByID(s->scene, g, geom_id);
    rtc.rtcReleaseGeometry(g);
    return s->d->error ? -1 : 0;
}

/* SoA accessors for N-wide rays and hits: Embree's own RTCRayN_* helpers
 * exist only in C++; this is the same layout (rtcore_ray.h), the ray's 12
 * fields then the hit's, each N wide. */
#define PT_RAYN_F(ray, N, i, field) (((float *)(ray))[(field) * (N) + (i)])
#define PT_RAYN_U(ray, N, i, field) (((unsigned *)(ray))[(field) * (N) + (i)])
#define PT_HITN_F(hit, N, i, field) (((float *)(hit))[(field) * (N) + (i)])
#define PT_HITN_U(hit, N, i, field) (((unsigned *)(hit))[(field) * (N) + (i)])
enum { R_ORG_X = 0, R_ORG_Y, R_ORG_Z, R_TNEAR, R_DIR_X, R_DIR_Y, R_DIR_Z, R_TIME, R_TFAR, R_MASK, R_ID, R_FLAGS, R_FIELDS };
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
    float *hit = ray + R_FIELDS * N;
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

static int scene_add_sphere(pt_scene *s, uint32_t geom_id, const float center_radius[4], pt_sphere_fn test) {
    RTCGeometry g = rtc.rtcNewGeometry(s->d->dev, RTC_GEOMETRY_TYPE_USER);
    if (!g) return -1;
    sphere_data *sd = (sphere_data *)malloc(sizeof *sd);
    if (!sd) {
        rtc.rtcReleaseGeometry(g);
        return -1;
    }
    memcpy(sd->cr, center_radius, sizeof sd->cr);
    sd->test = test;
    rtc.rtcSetGeometryUserPrimitiveCount(g, 1);
    rtc.rtcSetGeometryUserData(g, sd);
    rtc.rtcSetGeometryBoundsFunction(g, sphere_bounds, NULL);
    rtc.rtcSetGeometryIntersectFunction(g, sphere_intersect);
    rtc.rtcSetGeometryOccludedFunction(g, sphere_occluded);
    rtc.rtcSetGeometryMask(g, 0xFFFFFFFFu);
    rtc.rtcCommitGeometry(g);
    rtc.rtcAttachGeometryByID(s->scene, g, geom_id);
    /* The scene holds the geometry; free the user data with the scene. */
    rtc.rtcReleaseGeometry(g);
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

static int scene_commit(pt_scene *s) {
    rtc.rtcCommitScene(s->scene);
    return s->d->error ? -1 : 0;
}

static void scene_release(pt_scene *s) {
    if (!s) return;
    rtc.rtcReleaseScene(s->scene);
    for (size_t i = 0; i < s->n_owned; i++) free(s->owned[i]);
    free(s->owned);
    free(s);
}

/* --------------------------------------------------------------- traversal */

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

static void intersect1(const pt_scene *s, const pt_ray *ray, pt_hit *hit) {
    rayhit1 rh;
    to_rayhit(ray, &rh.v);
    ISECT1(query_of(0), s->scene, &rh.v);
    from_rayhit(&rh.v, hit);
}

static int occluded1(const pt_scene *s, const pt_ray *ray) {
    rayhit1 rh;
    to_rayhit(ray, &rh.v);
    OCC1(query_of(0), s->scene, &rh.v.ray);
    return rh.v.ray.tfar == -INFINITY;
}

/* Rays [0, m) of a packet of N into SoA form; lanes m..N invalid. */
static void load_packet(void *p, unsigned N, int *valid, const pt_ray *rays, size_t m) {
    float *ray = (float *)p;
    float *hit = ray + R_FIELDS * N;
    for (unsigned k = 0; k < N; k++) {
        if (k >= m) {
            valid[k] = 0;
            PT_RAYN_F(ray, N, k, R_TNEAR) = 0.0f;
            PT_RAYN_F(ray, N, k, R_TFAR) = -INFINITY;
            continue;
        }
        const pt_ray *r = &rays[k];
        valid[k] = -1;
        PT_RAYN_F(ray, N, k, R_ORG_X) = r->org[0];
        PT_RAYN_F(ray, N, k, R_ORG_Y) = r->org[1];
        PT_RAYN_F(ray, N, k, R_ORG_Z) = r->org[2];
        PT_RAYN_F(ray, N, k, R_DIR_X) = r->dir[0];
        PT_RAYN_F(ray, N, k, R_DIR_Y) = r->dir[1];
        PT_RAYN_F(ray, N, k, R_DIR_Z) = r->dir[2];
        PT_RAYN_F(ray, N, k, R_TNEAR) = next_up(r->tnear);
        PT_RAYN_F(ray, N, k, R_TFAR) = r->tfar;
        PT_RAYN_F(ray, N, k, R_TIME) = 0.0f;
        PT_RAYN_U(ray, N, k, R_MASK) = 0xFFFFFFFFu;
        PT_RAYN_U(ray, N, k, R_ID) = k;
        PT_RAYN_U(ray, N, k, R_FLAGS) = 0;
        PT_HITN_U(hit, N, k, H_GEOM) = RTC_INVALID_GEOMETRY_ID;
        PT_HITN_U(hit, N, k, H_PRIM) = RTC_INVALID_GEOMETRY_ID;
        PT_HITN_U(hit, N, k, H_INST0) = RTC_INVALID_GEOMETRY_ID;
    }
}

static unsigned packet_width(int mode) { return mode == PT_BATCH_PACKET4 ? 4 : mode == PT_BATCH_PACKET16 ? 16 : 8; }

static void intersect_packet(query *q, const pt_scene *s, unsigned N, int *valid, void *p) {
    switch (N) {
    case 4: ISECTN(4, q, valid, s->scene, p); break;
    case 8: ISECTN(8, q, valid, s->scene, p); break;
    default: ISECTN(16, q, valid, s->scene, p); break;
    }
}

static void occluded_packet(query *q, const pt_scene *s, unsigned N, int *valid, void *p) {
    switch (N) {
    case 4: OCCN(4, q, valid, s->scene, p); break;
    case 8: OCCN(8, q, valid, s->scene, p); break;
    default: OCCN(16, q, valid, s->scene, p); break;
    }
}

static void intersect_batch(const pt_scene *s, const pt_ray *rays, pt_hit *hits, size_t n, int mode, int coherent) {
    query *q = query_of(coherent);
    if (mode == PT_BATCH_PACKET4 || mode == PT_BATCH_PACKET8 || mode == PT_BATCH_PACKET16) {
        unsigned N = packet_width(mode);
        for (size_t i = 0; i < n; i += N) {
            RTC_ALIGN(64) int valid[16];
            packet p;
            size_t m = n - i < N ? n - i : N;
            load_packet(p.bytes, N, valid, rays + i, m);
            intersect_packet(q, s, N, valid, p.bytes);
            float *ray = (float *)p.bytes;
            float *hit = ray + R_FIELDS * N;
            for (size_t k = 0; k < m; k++) {
                hits[i + k].geom_id = PT_HITN_U(hit, N, k, H_GEOM);
                hits[i + k].prim_id = PT_HITN_U(hit, N, k, H_PRIM);
                hits[i + k].t = PT_RAYN_F(ray, N, k, R_TFAR);
                hits[i + k].u = PT_HITN_F(hit, N, k, H_U);
                hits[i + k].v = PT_HITN_F(hit, N, k, H_V);
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
            rtc.rtcIntersect1M(s->scene, &q->ctx, buf, (unsigned)m, sizeof(struct RTCRayHit));
            for (size_t k = 0; k < m; k++) from_rayhit(&buf[k], &hits[i + k]);
        }
        return;
    }
#endif
    for (size_t i = 0; i < n; i++) {
        rayhit1 rh;
        to_rayhit(&rays[i], &rh.v);
        ISECT1(q, s->scene, &rh.v);
        from_rayhit(&rh.v, &hits[i]);
    }
}

static void occluded_batch(const pt_scene *s, const pt_ray *rays, uint8_t *occluded, size_t n, int mode, int coherent) {
    query *q = query_of(coherent);
    if (mode == PT_BATCH_PACKET4 || mode == PT_BATCH_PACKET8 || mode == PT_BATCH_PACKET16) {
        unsigned N = packet_width(mode);
        for (size_t i = 0; i < n; i += N) {
            RTC_ALIGN(64) int valid[16];
            packet p;
            size_t m = n - i < N ? n - i : N;
            load_packet(p.bytes, N, valid, rays + i, m);
            occluded_packet(q, s, N, valid, p.bytes);
            for (size_t k = 0; k < m; k++) occluded[i + k] = PT_RAYN_F(p.bytes, N, k, R_TFAR) == -INFINITY;
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
            rtc.rtcOccluded1M(s->scene, &q->ctx, (struct RTCRay *)buf, (unsigned)m, sizeof(struct RTCRayHit));
            for (size_t k = 0; k < m; k++) occluded[i + k] = buf[k].ray.tfar == -INFINITY;
        }
        return;
    }
#endif
    for (size_t i = 0; i < n; i++) {
        rayhit1 rh;
        to_rayhit(&rays[i], &rh.v);
        OCC1(q, s->scene, &rh.v.ray);
        occluded[i] = rh.v.ray.tfar == -INFINITY;
    }
}

/* -------------------------------------------------------------- ABI canary */

/* How many of the PT_PAD bytes after a `width`-ray hit structure the library
 * writes when it reports a hit, found with two fill patterns (a byte the
 * library writes might equal one of them). -1 on error. */
static int abi_probe(int width) {
    if (load()) return -1;
    pt_device *d = device_new(NULL);
    if (!d) return -1;
    pt_scene *s = scene_new(d, 1, 1);
    const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint32_t tri[3] = {0, 1, 2};
    int result = -1;
    if (s && scene_add_mesh(s, 0, xyz, 3, tri, 1) == 0 && scene_commit(s) == 0) {
        const pt_ray r = {{0.25f, 0.25f, -1.0f}, 0.0f, {0.0f, 0.0f, 1.0f}, 10.0f};
        result = 0;
        for (int pass = 0; pass < 2 && result >= 0; pass++) {
            unsigned char fill = pass ? 0x5A : 0xA5;
            query q;
            query_init(&q, 0);
            packet p;
            size_t size;
            memset(p.bytes, fill, sizeof p.bytes);
            unsigned geom;
            if (width == 1) {
                size = sizeof(struct RTCRayHit);
                to_rayhit(&r, (struct RTCRayHit *)p.bytes);
                ISECT1(&q, s->scene, (struct RTCRayHit *)p.bytes);
                geom = ((struct RTCRayHit *)p.bytes)->hit.geomID;
            } else if (width == 4 || width == 8 || width == 16) {
                size = width == 4 ? sizeof(struct RTCRayHit4) : width == 8 ? sizeof(struct RTCRayHit8) : sizeof(struct RTCRayHit16);
                RTC_ALIGN(64) int valid[16];
                /* Every lane a valid ray (so a lane-wise write shows). */
                pt_ray rs[16];
                for (int k = 0; k < 16; k++) rs[k] = r;
                load_packet(p.bytes, (unsigned)width, valid, rs, (size_t)width);
                intersect_packet(&q, s, (unsigned)width, valid, p.bytes);
                geom = PT_HITN_U((float *)p.bytes + R_FIELDS * width, (unsigned)width, 0, H_GEOM);
            } else {
                result = -1;
                break;
            }
            if (geom != 0) {
                result = -1;
                break;
            }
            for (size_t k = sizeof p.bytes; k > size; k--) {
                if (p.bytes[k - 1] != fill) {
                    if ((int)(k - size) > result) result = (int)(k - size);
                    break;
                }
            }
        }
    }
    scene_release(s);
    device_release(d);
    return result;
}

/* ------------------------------------------------------------------- table */

#define PT_STR2(x) #x
#define PT_STR(x) PT_STR2(x)

static const pt_api api = {
    .major = RTC_VERSION_MAJOR,
    .header_version = RTC_VERSION,
    .library = PT_EMBREE_LIBS,
    .load = load,
    .library_version = library_version,
    .device_new = device_new,
    .device_new_error = device_new_error,
    .device_release = device_release,
    .device_take_error = device_take_error,
    .device_memory = device_memory,
    .device_has_streams = device_has_streams,
    .scene_new = scene_new,
    .scene_add_mesh = scene_add_mesh,
    .scene_add_sphere = scene_add_sphere,
    .scene_commit = scene_commit,
    .scene_release = scene_release,
    .intersect1 = intersect1,
    .occluded1 = occluded1,
    .intersect_batch = intersect_batch,
    .occluded_batch = occluded_batch,
    .abi_probe = abi_probe,
    .abi_padding = PT_PAD,
};

const pt_api *PT_API_FN(void) { return &api; }
