/* tinybvh's single-ray traversal in a C++ loop: the second mesh anchor, beside
 * scripts/embree_trace.c (Embree 4). scripts/anchor_tinybvh.py compiles it (the system C++
 * compiler, -O3 -march=native) against tiny_bvh.h, which is not part of this repository:
 * the header comes from $TINYBVH_DIR (a checkout of github.com/jbikker/tinybvh, MIT licence)
 * at run time.
 *
 *   tinybvh_trace TRIS LAYOUT QUERY RAYS REPEATS OUT
 *
 * TRIS: the triangles `anchor_rays export` writes (tris.f32: 9 little-endian f32 per
 * triangle, v0 v1 v2, render space). LAYOUT: which tinybvh layout to build and trace:
 *   bvh8   BVH8_CPU  (8-wide nodes, 4-triangle SoA leaves; AVX2 + FMA)
 *   bvh4   BVH4_CPU  (4-wide nodes, 4-triangle SoA leaves; SSE)
 *   soa    BVH_SoA   (binary nodes, child boxes as SoA; AVX)
 *   bvh    BVH       (the plain binary reference layout)
 * each built with the layout's Build (binned SAH; BuildAVX underneath when AVX is on), or with
 * a suffix `-hq` with BuildHQ (spatial splits, the builder tinybvh's own speed test uses).
 * QUERY: `camera` (RAYS holds 6 f32 per ray, origin and direction, as `anchor_rays export`'s
 * rays.f32; closest hit, tmax +inf), `closest` (7 f32 per ray, origin, direction, tmax;
 * closest hit) or `occluded` (7 f32 per ray; occlusion query). tmin is 0 throughout (the
 * library's triangle test accepts t > 0), as Embree's tnear 0.
 *
 * Prints `build WALL_S CPU_S BYTES` (the BVH's build: wall seconds, the process's CPU
 * seconds over every thread (tinybvh builds meshes above 50,000 triangles on several
 * threads), and the bytes of the layout's nodes in use, leaves included for BVH8_CPU and
 * BVH4_CPU, whose leaves hold their triangles), then, after one untimed warm-up pass, one
 * `Mrays/s count` line per timed pass (the tracing thread's CPU time, CLOCK_THREAD_CPUTIME_ID,
 * as embree_trace.c and anchor_rays time theirs; count: rays that hit or are occluded), and
 * writes each ray's answer of the last pass to OUT as little-endian f32: the hit distance
 * (+inf on a miss) or 1 / 0 for occluded / not.
 *
 * Rays are set up field by field in the timed loop (origin, direction as given (the library's
 * Ray constructor would normalise it again and change its bits), reciprocal direction through
 * the library's tinybvh_rcp, tmax), as embree_trace.c fills its RTCRayHit per call.
 */
#define TINYBVH_IMPLEMENTATION
#include "tiny_bvh.h"

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <type_traits>
#include <time.h>
#include <vector>

using namespace tinybvh;

static double clock_seconds(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static std::vector<float> read_f32(const char *path, size_t per, const char *what) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "tinybvh_trace: cannot open %s (%s)\n", path, what);
        exit(2);
    }
    std::vector<float> v;
    float buf[4096];
    size_t n;
    while ((n = fread(buf, sizeof(float), 4096, f)) > 0) v.insert(v.end(), buf, buf + n);
    fclose(f);
    if (v.empty() || v.size() % per != 0) {
        fprintf(stderr, "tinybvh_trace: %s: %zu floats, not a positive multiple of %zu (%s)\n",
                path, v.size(), per, what);
        exit(2);
    }
    return v;
}

/* The ray fields from `r` (origin r[0..3], direction r[3..6]) and tmax `tf`. */
static inline void set_ray(Ray &ray, const float *r, float tf) {
    ray.O = bvhvec3(r[0], r[1], r[2]);
    ray.D = bvhvec3(r[3], r[4], r[5]);
    ray.rD = tinybvh_rcp(ray.D);
    ray.mask = RAY_MASK_INTERSECT_ALL;
    ray.instIdx = 0;
    ray.hit.t = tf;
    ray.hit.u = ray.hit.v = 0.0f;
    ray.hit.prim = 0xffffffffu;
}

template <class B>
static long pass(const B &bvh, const float *rays, size_t nray, size_t stride, int query,
                 float *t_out) {
    long found = 0;
    Ray ray{};
    for (size_t i = 0; i < nray; i++) {
        const float *r = rays + stride * i;
        const float tf = stride == 7 ? r[6] : INFINITY;
        set_ray(ray, r, tf);
        if (query == 2) {
            const bool occluded = bvh.IsOccluded(ray);
            found += occluded;
            if (t_out) t_out[i] = occluded ? 1.0f : 0.0f;
        } else {
            bvh.Intersect(ray);
            const bool hit = ray.hit.t < tf;
            found += hit;
            if (t_out) t_out[i] = hit ? ray.hit.t : INFINITY;
        }
    }
    return found;
}

/* The bytes of the layout's nodes in use: BVH8_CPU and BVH4_CPU count 64-byte cache lines
 * of interior nodes and 4-triangle leaves; the others count nodes. */
template <class B> static size_t used_bytes(const B &bvh) {
    if constexpr (std::is_same_v<B, BVH8_CPU> || std::is_same_v<B, BVH4_CPU>)
        return (size_t)bvh.usedBlocks * 64;
    else
        return (size_t)bvh.usedNodes * sizeof(typename B::BVHNode);
}

template <class B>
static int run(B &bvh, bool hq, const std::vector<bvhvec4> &verts, size_t ntri,
               const std::vector<float> &rays, size_t stride, int query, int repeats,
               const char *out_path) {
    const double w0 = clock_seconds(CLOCK_MONOTONIC), c0 = clock_seconds(CLOCK_PROCESS_CPUTIME_ID);
    if (hq)
        bvh.BuildHQ(verts.data(), (uint32_t)ntri);
    else
        bvh.Build(verts.data(), (uint32_t)ntri);
    const double w1 = clock_seconds(CLOCK_MONOTONIC), c1 = clock_seconds(CLOCK_PROCESS_CPUTIME_ID);
    printf("build %.6f %.6f %zu\n", w1 - w0, c1 - c0, used_bytes(bvh));
    const size_t nray = rays.size() / stride;
    std::vector<float> t(nray);
    long found = 0;
    for (int k = -1; k < repeats; k++) {
        const double t0 = clock_seconds(CLOCK_THREAD_CPUTIME_ID);
        found = pass(bvh, rays.data(), nray, stride, query, k == repeats - 1 ? t.data() : nullptr);
        const double dt = clock_seconds(CLOCK_THREAD_CPUTIME_ID) - t0;
        if (k >= 0) printf("%.6f %ld\n", (double)nray / (dt > 1e-12 ? dt : 1e-12) / 1e6, found);
    }
    FILE *f = fopen(out_path, "wb");
    if (!f || fwrite(t.data(), sizeof(float), nray, f) != nray || fclose(f) != 0) {
        fprintf(stderr, "tinybvh_trace: cannot write %s\n", out_path);
        return 2;
    }
    return 0;
}

int main(int argc, char **argv) {
    const char *usage = "usage: tinybvh_trace TRIS bvh8|bvh4|soa|bvh[-hq] camera|closest|occluded "
                        "RAYS REPEATS OUT";
    if (argc != 7) {
        fprintf(stderr, "%s\n", usage);
        return 2;
    }
    std::string layout = argv[2];
    bool hq = false;
    if (layout.size() > 3 && layout.compare(layout.size() - 3, 3, "-hq") == 0) {
        hq = true;
        layout.resize(layout.size() - 3);
    }
    const std::string q = argv[3];
    const int query = q == "camera" ? 0 : q == "closest" ? 1 : q == "occluded" ? 2 : -1;
    const int repeats = atoi(argv[5]);
    if (query < 0 || repeats < 1) {
        fprintf(stderr, "%s\n", usage);
        return 2;
    }
    const std::vector<float> tris = read_f32(argv[1], 9, "triangles");
    const size_t stride = query == 0 ? 6 : 7;
    const std::vector<float> rays = read_f32(argv[4], stride, "rays");
    const size_t ntri = tris.size() / 9;
    // tinybvh takes vertices as 16-byte bvhvec4 (x, y, z, unused), three per triangle.
    std::vector<bvhvec4> verts(3 * ntri);
    for (size_t i = 0; i < 3 * ntri; i++)
        verts[i] = bvhvec4(tris[3 * i], tris[3 * i + 1], tris[3 * i + 2], 0.0f);
    if (layout == "bvh8") {
        BVH8_CPU bvh;
        return run(bvh, hq, verts, ntri, rays, stride, query, repeats, argv[6]);
    } else if (layout == "bvh4") {
        BVH4_CPU bvh;
        return run(bvh, hq, verts, ntri, rays, stride, query, repeats, argv[6]);
    } else if (layout == "soa") {
        BVH_SoA bvh;
        return run(bvh, hq, verts, ntri, rays, stride, query, repeats, argv[6]);
    } else if (layout == "bvh") {
        BVH bvh;
        return run(bvh, hq, verts, ntri, rays, stride, query, repeats, argv[6]);
    }
    fprintf(stderr, "tinybvh_trace: unknown layout `%s`\n%s\n", argv[2], usage);
    return 2;
}
