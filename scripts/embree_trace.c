/* Embree 4's single-ray rtcIntersect1 in a C loop, for scripts/anchor_embree.py (and, for
 * the incoherent rays, rtcOccluded1 and the 8-wide rtcIntersect8 / rtcOccluded8).
 *
 * The embreex wheel ships libembree4 but its EmbreeScene sets RTC_SCENE_FLAG_ROBUST by default
 * (embreex 4.x, `robust=True`), exposes no build quality, and its Python-called loop writes
 * u, v, Ng, primID, geomID and tfar into fresh NumPy arrays around every call. Measured on
 * this machine (2026-11-26, load 0.4) that loop ran Embree 0.70-0.74x as fast as this one on
 * the bunny and 0.86-0.89x on the full dragon, so it is not Embree's single-ray speed.
 * anchor_embree.py compiles this file with the system C compiler into a shared library that
 * resolves against the wheel's libembree4 (no Embree headers needed: the few declarations
 * below follow Embree 4's rtcore_*.h) and traces the rays one rtcIntersect1 call each on the
 * calling thread, timed with the thread's CPU clock (as anchor_rays times marchmesh).
 *
 * Build quality (rtcSetSceneBuildQuality): 0 low, 1 medium (Embree's default, binned SAH),
 * 2 high (spatial splits). Scene flags (rtcSetSceneFlags): 0 none (Embree's default),
 * 4 robust.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <time.h>

typedef struct RTCDeviceTy *RTCDevice;
typedef struct RTCSceneTy *RTCScene;
typedef struct RTCGeometryTy *RTCGeometry;

RTCDevice rtcNewDevice(const char *config);
void rtcReleaseDevice(RTCDevice device);
int rtcGetDeviceError(RTCDevice device);
RTCScene rtcNewScene(RTCDevice device);
void rtcReleaseScene(RTCScene scene);
void rtcSetSceneBuildQuality(RTCScene scene, int quality);
void rtcSetSceneFlags(RTCScene scene, int flags);
void rtcCommitScene(RTCScene scene);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void rtcSetGeometryBuildQuality(RTCGeometry geometry, int quality);
void *rtcSetNewGeometryBuffer(RTCGeometry geometry, int type, unsigned int slot, int format,
                              size_t byte_stride, size_t item_count);
void rtcCommitGeometry(RTCGeometry geometry);
unsigned int rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);

enum {
    GEOMETRY_TYPE_TRIANGLE = 0,
    BUFFER_TYPE_INDEX = 0,
    BUFFER_TYPE_VERTEX = 1,
    FORMAT_UINT3 = 0x5003,
    FORMAT_FLOAT3 = 0x9003,
};
#define INVALID_ID 0xffffffffu

/* struct RTCRayHit of rtcore_ray.h. The hit part is padded: with instance arrays compiled in,
 * Embree's RTCHit carries one more id than the 7 fields below. */
struct __attribute__((aligned(16))) RayHit {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned int mask, id, flags;
    float ng_x, ng_y, ng_z, u, v;
    unsigned int prim_id, geom_id, inst_id[1];
    unsigned int pad[8];
};

void rtcIntersect1(RTCScene scene, struct RayHit *rayhit, void *args);

/* struct RTCRayHit8 of rtcore_ray.h: 8 rays as structure of arrays, hit part padded as above. */
struct __attribute__((aligned(32))) RayHit8 {
    float org_x[8], org_y[8], org_z[8], tnear[8];
    float dir_x[8], dir_y[8], dir_z[8], time[8];
    float tfar[8];
    unsigned int mask[8], id[8], flags[8];
    float ng_x[8], ng_y[8], ng_z[8], u[8], v[8];
    unsigned int prim_id[8], geom_id[8], inst_id[1][8];
    unsigned int pad[8][8];
};

void rtcIntersect8(const int *valid, RTCScene scene, struct RayHit8 *rayhit, void *args);

/* struct RTCRay of rtcore_ray.h (the ray part of RTCRayHit; rtcOccluded1 sets tfar to -inf
 * when the ray is occluded). */
struct __attribute__((aligned(16))) Ray {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned int mask, id, flags;
};

void rtcOccluded1(RTCScene scene, struct Ray *ray, void *args);

/* struct RTCRay8 of rtcore_ray.h. */
struct __attribute__((aligned(32))) Ray8 {
    float org_x[8], org_y[8], org_z[8], tnear[8];
    float dir_x[8], dir_y[8], dir_z[8], time[8];
    float tfar[8];
    unsigned int mask[8], id[8], flags[8];
};

void rtcOccluded8(const int *valid, RTCScene scene, struct Ray8 *ray, void *args);

static double thread_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Builds a scene of `ntri` triangles (9 floats each: v0 v1 v2) with build `quality` and scene
 * `flags` (rtcSetSceneFlags: 0 none, 4 robust). Returns the scene, or NULL with *error set:
 * -1 no device, -2 no geometry buffers, -3 Embree reported an error. */
RTCScene anchor_build(const float *tris, size_t ntri, int quality, int flags, int *error) {
    *error = 0;
    RTCDevice device = rtcNewDevice(NULL);
    if (!device) {
        *error = -1;
        return NULL;
    }
    RTCScene scene = rtcNewScene(device);
    rtcSetSceneFlags(scene, flags);
    rtcSetSceneBuildQuality(scene, quality);
    RTCGeometry geom = rtcNewGeometry(device, GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(geom, quality);
    float *vertices = rtcSetNewGeometryBuffer(geom, BUFFER_TYPE_VERTEX, 0, FORMAT_FLOAT3,
                                              3 * sizeof(float), 3 * ntri);
    unsigned int *indices = rtcSetNewGeometryBuffer(geom, BUFFER_TYPE_INDEX, 0, FORMAT_UINT3,
                                                    3 * sizeof(unsigned int), ntri);
    if (!vertices || !indices) {
        rtcReleaseGeometry(geom);
        rtcReleaseScene(scene);
        rtcReleaseDevice(device);
        *error = -2;
        return NULL;
    }
    memcpy(vertices, tris, 9 * ntri * sizeof(float));
    for (size_t i = 0; i < 3 * ntri; i++) indices[i] = (unsigned int)i;
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    if (rtcGetDeviceError(device) != 0) {
        rtcReleaseScene(scene);
        rtcReleaseDevice(device);
        *error = -3;
        return NULL;
    }
    /* The scene keeps its own reference to the device. */
    rtcReleaseDevice(device);
    return scene;
}

/* The ray fields of one ray (struct Ray or struct RayHit) from `r`: origin r[0..3], direction
 * r[3..6], tnear 0, tfar `tf`, every ray mask bit set. */
#define SET_RAY1(x, r, tf)                                                                    \
    ((x).org_x = (r)[0], (x).org_y = (r)[1], (x).org_z = (r)[2], (x).tnear = 0.0f,           \
     (x).dir_x = (r)[3], (x).dir_y = (r)[4], (x).dir_z = (r)[5], (x).time = 0.0f,            \
     (x).tfar = (tf), (x).mask = INVALID_ID, (x).id = 0, (x).flags = 0)

/* SET_RAY1 for lane `k` of a packet (struct Ray8 or struct RayHit8). */
#define SET_RAY8(x, k, r, tf)                                                                 \
    ((x).org_x[k] = (r)[0], (x).org_y[k] = (r)[1], (x).org_z[k] = (r)[2], (x).tnear[k] = 0.0f, \
     (x).dir_x[k] = (r)[3], (x).dir_y[k] = (r)[4], (x).dir_z[k] = (r)[5], (x).time[k] = 0.0f,  \
     (x).tfar[k] = (tf), (x).mask[k] = INVALID_ID, (x).id[k] = 0, (x).flags[k] = 0)

/* One pass of rtcIntersect1 calls over `nray` rays (6 floats each: origin, direction;
 * tnear 0, tfar +inf); writes each hit distance into t_out (+inf on a miss) unless it is
 * NULL; returns the number of rays that hit. */
static long single_pass(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t i = 0; i < nray; i++) {
        const float *r = rays + 6 * i;
        struct RayHit rh;
        SET_RAY1(rh, r, INFINITY);
        rh.geom_id = INVALID_ID, rh.inst_id[0] = INVALID_ID;
        rtcIntersect1(scene, &rh, NULL);
        int hit = rh.geom_id != INVALID_ID;
        found += hit;
        if (t_out) t_out[i] = hit ? rh.tfar : INFINITY;
    }
    return found;
}

/* single_pass with Embree's 8-ray packets: rays 8k..8k+7 (in the order given) are one
 * rtcIntersect8 call; a last partial packet has its missing lanes switched off. */
static long packet_pass(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t first = 0; first < nray; first += 8) {
        struct RayHit8 rh;
        int valid[8];
        for (int k = 0; k < 8; k++) {
            size_t i = first + (size_t)k;
            const float *r = rays + 6 * (i < nray ? i : first);
            valid[k] = i < nray ? -1 : 0;
            SET_RAY8(rh, k, r, INFINITY);
            rh.geom_id[k] = INVALID_ID, rh.inst_id[0][k] = INVALID_ID;
        }
        rtcIntersect8(valid, scene, &rh, NULL);
        for (int k = 0; k < 8 && first + (size_t)k < nray; k++) {
            int hit = rh.geom_id[k] != INVALID_ID;
            found += hit;
            if (t_out) t_out[first + (size_t)k] = hit ? rh.tfar[k] : INFINITY;
        }
    }
    return found;
}

/* One warm-up pass of `pass`, then `repeats` timed passes, each rate (Mrays/s of the
 * thread's CPU time) into rates[k]; the last pass's hit distances go into t_out. Returns
 * the number of rays that hit. */
static long timed(long (*pass)(RTCScene, const float *, size_t, float *), RTCScene scene,
                  const float *rays, size_t nray, int repeats, double *rates, float *t_out) {
    long found = 0;
    for (int k = -1; k < repeats; k++) {
        double t0 = thread_seconds();
        found = pass(scene, rays, nray, k == repeats - 1 ? t_out : NULL);
        double dt = thread_seconds() - t0;
        if (k >= 0) rates[k] = (double)nray / (dt > 1e-12 ? dt : 1e-12) / 1e6;
    }
    return found;
}

/* Single rays (rtcIntersect1): see `timed`. */
long anchor_trace(RTCScene scene, const float *rays, size_t nray, int repeats, double *rates,
                  float *t_out) {
    return timed(single_pass, scene, rays, nray, repeats, rates, t_out);
}

/* 8-ray packets (rtcIntersect8), rays 8k..8k+7 one packet: see `timed`. */
long anchor_trace8(RTCScene scene, const float *rays, size_t nray, int repeats, double *rates,
                   float *t_out) {
    return timed(packet_pass, scene, rays, nray, repeats, rates, t_out);
}

/* The incoherent rays: 7 floats each (origin, direction, tfar), tnear 0. */

/* rtcIntersect1 per ray up to its own tfar; t_out as single_pass. */
static long intersect1_pass7(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t i = 0; i < nray; i++) {
        const float *r = rays + 7 * i;
        struct RayHit rh;
        SET_RAY1(rh, r, r[6]);
        rh.geom_id = INVALID_ID, rh.inst_id[0] = INVALID_ID;
        rtcIntersect1(scene, &rh, NULL);
        int hit = rh.geom_id != INVALID_ID;
        found += hit;
        if (t_out) t_out[i] = hit ? rh.tfar : INFINITY;
    }
    return found;
}

/* rtcOccluded1 per ray; t_out[i] is 1 for an occluded ray, 0 otherwise; returns the number
 * of occluded rays. */
static long occluded1_pass7(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t i = 0; i < nray; i++) {
        const float *r = rays + 7 * i;
        struct Ray ray;
        SET_RAY1(ray, r, r[6]);
        rtcOccluded1(scene, &ray, NULL);
        int occluded = ray.tfar < 0.0f;
        found += occluded;
        if (t_out) t_out[i] = occluded ? 1.0f : 0.0f;
    }
    return found;
}

/* intersect1_pass7 with rtcIntersect8 on rays 8k..8k+7 (a last partial packet masked). */
static long intersect8_pass7(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t first = 0; first < nray; first += 8) {
        struct RayHit8 rh;
        int valid[8];
        for (int k = 0; k < 8; k++) {
            size_t i = first + (size_t)k;
            const float *r = rays + 7 * (i < nray ? i : first);
            valid[k] = i < nray ? -1 : 0;
            SET_RAY8(rh, k, r, r[6]);
            rh.geom_id[k] = INVALID_ID, rh.inst_id[0][k] = INVALID_ID;
        }
        rtcIntersect8(valid, scene, &rh, NULL);
        for (int k = 0; k < 8 && first + (size_t)k < nray; k++) {
            int hit = rh.geom_id[k] != INVALID_ID;
            found += hit;
            if (t_out) t_out[first + (size_t)k] = hit ? rh.tfar[k] : INFINITY;
        }
    }
    return found;
}

/* occluded1_pass7 with rtcOccluded8 on rays 8k..8k+7 (a last partial packet masked). */
static long occluded8_pass7(RTCScene scene, const float *rays, size_t nray, float *t_out) {
    long found = 0;
    for (size_t first = 0; first < nray; first += 8) {
        struct Ray8 ray;
        int valid[8];
        for (int k = 0; k < 8; k++) {
            size_t i = first + (size_t)k;
            const float *r = rays + 7 * (i < nray ? i : first);
            valid[k] = i < nray ? -1 : 0;
            SET_RAY8(ray, k, r, r[6]);
        }
        rtcOccluded8(valid, scene, &ray, NULL);
        for (int k = 0; k < 8 && first + (size_t)k < nray; k++) {
            int occluded = ray.tfar[k] < 0.0f;
            found += occluded;
            if (t_out) t_out[first + (size_t)k] = occluded ? 1.0f : 0.0f;
        }
    }
    return found;
}

/* Rays of 7 floats (origin, direction, tfar) with `query` 0 rtcIntersect1, 1 rtcOccluded1,
 * 2 rtcIntersect8, 3 rtcOccluded8 (8 consecutive rays a packet): see `timed`. t_out holds
 * hit distances (+inf on a miss) for the intersections, 1 or 0 (occluded or not) for the
 * occlusion queries; returns the number of hits or occluded rays, -1 for an unknown query. */
long anchor_trace_rays(RTCScene scene, const float *rays, size_t nray, int query, int repeats,
                       double *rates, float *t_out) {
    static long (*const passes[4])(RTCScene, const float *, size_t, float *) = {
        intersect1_pass7, occluded1_pass7, intersect8_pass7, occluded8_pass7};
    if (query < 0 || query > 3) return -1;
    return timed(passes[query], scene, rays, nray, repeats, rates, t_out);
}

/* anchor_trace's single pass with each hit's triangle: t_out as single_pass, prim_out the
 * hit triangle's index (0xffffffff on a miss). Untimed: the incoherent rays start at these
 * hits. */
long anchor_primary_hits(RTCScene scene, const float *rays, size_t nray, float *t_out,
                         unsigned int *prim_out) {
    long found = 0;
    for (size_t i = 0; i < nray; i++) {
        const float *r = rays + 6 * i;
        struct RayHit rh;
        SET_RAY1(rh, r, INFINITY);
        rh.geom_id = INVALID_ID, rh.inst_id[0] = INVALID_ID;
        rtcIntersect1(scene, &rh, NULL);
        int hit = rh.geom_id != INVALID_ID;
        found += hit;
        t_out[i] = hit ? rh.tfar : INFINITY;
        prim_out[i] = hit ? rh.prim_id : INVALID_ID;
    }
    return found;
}

/* Releases a scene from anchor_build (and with it its device). */
void anchor_release(RTCScene scene) { rtcReleaseScene(scene); }
