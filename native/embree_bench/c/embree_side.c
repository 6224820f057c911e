/* RingTracer's side-by-side harness for Intel Embree 3 (Debian libembree-dev).
 *
 * A triangle mesh is handed over once (eb_new) and Embree builds its BVH; then the caller
 * times batches of rays through eb_intersect1 (one rtcIntersect1 per ray), eb_intersect16
 * (rtcIntersect16 on consecutive groups of 16 rays; the caller orders coherent rays in tiles)
 * and the shadow forms eb_occluded1 / eb_occluded16. Rays are 6 floats each (origin, unit
 * direction), tnear 0, tfar infinity. Each call returns the number of rays that hit.
 * eb_build_figures builds a mesh's BVH once more for its build time and SAH figure. */
#include <embree3/rtcore.h>
#include <stdint.h>
#include <stddef.h>
#include <string.h>
#include <stdio.h>
#include <time.h>
#include <unistd.h>

struct eb_scene {
  RTCDevice device;
  RTCScene scene;
};

static struct eb_scene the_scenes[8];
/* the_claimed[i] != 0: slot i belongs to one eb_new or to its handle until eb_free. A slot is
 * claimed with one atomic exchange, so that two threads building scenes at once never get the
 * same handle. */
static int the_claimed[8];

static int claim_slot(void) {
  for (int i = 0; i < 8; i++)
    if (__atomic_exchange_n(&the_claimed[i], 1, __ATOMIC_ACQ_REL) == 0) return i;
  return -1;
}

static void release_slot(int h) { __atomic_store_n(&the_claimed[h], 0, __ATOMIC_RELEASE); }

const char *eb_version(void) { return RTC_VERSION_STRING; }

/* The mesh as Embree's scene on `device`, committed only when `commit` is set; NULL when
 * Embree refuses a buffer. */
static RTCScene mesh_scene(RTCDevice device, const float *verts, size_t nverts,
                           const uint32_t *idx, size_t ntris, int commit) {
  RTCScene scene = rtcNewScene(device);
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *v = (float *)rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0,
                                              RTC_FORMAT_FLOAT3, 3 * sizeof(float), nverts);
  unsigned *t = (unsigned *)rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0,
                                                    RTC_FORMAT_UINT3, 3 * sizeof(unsigned), ntris);
  if (v == NULL || t == NULL) {
    rtcReleaseGeometry(geom);
    rtcReleaseScene(scene);
    return NULL;
  }
  memcpy(v, verts, nverts * 3 * sizeof(float));
  memcpy(t, idx, ntris * 3 * sizeof(unsigned));
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  if (commit) rtcCommitScene(scene);
  return scene;
}

/* Returns a handle >= 0, or -1 when Embree refuses the device or the scene. `config` is the
 * device's configuration string (the caller passes one of a fixed set: "threads=1", optionally
 * with ",isa=..."). */
int eb_new(const float *verts, size_t nverts, const uint32_t *idx, size_t ntris,
           const char *config) {
  int h = claim_slot();
  if (h < 0) return -1;
  /* one build thread (in config): the machine is shared and the figures are per tracing thread */
  RTCDevice device = rtcNewDevice(config);
  if (device == NULL) {
    release_slot(h);
    return -1;
  }
  RTCScene scene = mesh_scene(device, verts, nverts, idx, ntris, 1);
  if (scene == NULL || rtcGetDeviceError(device) != RTC_ERROR_NONE) {
    if (scene != NULL) rtcReleaseScene(scene);
    rtcReleaseDevice(device);
    release_slot(h);
    return -1;
  }
  the_scenes[h].device = device;
  the_scenes[h].scene = scene;
  return h;
}

static double clock_seconds(clockid_t clock) {
  struct timespec ts;
  clock_gettime(clock, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The process's CPU time (all its threads), seconds: on a shared machine, a build's CPU time
 * varies much less than its wall time. */
double eb_cpu_seconds(void) { return clock_seconds(CLOCK_PROCESS_CPUTIME_ID); }

/* Builds the mesh's BVH once on a device of `config` (which must ask for `benchmark=1`) and
 * gives: in commit_s the wall time of rtcCommitScene, in cpu_s the process's CPU time over
 * it; in build_s and sah the figures of the
 * BENCHMARK_BUILD line Embree prints in benchmark mode (its own clock around the BVH build,
 * from the triangles to the finished tree, and the SAH of its BVH statistics). That line goes
 * to the standard output, which is sent to a temporary file for the commit (the process's
 * file descriptor 1: call with no other thread writing to it). Returns 0; -1 when the
 * device, the scene or the capture cannot be made; -2 when file descriptor 1 could not be
 * redirected; -100 - E when the device reports error E after the commit; -3 when no such
 * line was printed. */
int eb_build_figures(const float *verts, size_t nverts, const uint32_t *idx, size_t ntris,
                     const char *config, double *commit_s, double *cpu_s, double *build_s,
                     double *sah) {
  RTCDevice device = rtcNewDevice(config);
  if (device == NULL) return -1;
  RTCScene scene = mesh_scene(device, verts, nverts, idx, ntris, 0);
  FILE *capture = tmpfile();
  int saved = dup(1);
  if (scene == NULL || capture == NULL || saved < 0) {
    if (scene != NULL) rtcReleaseScene(scene);
    if (capture != NULL) fclose(capture);
    if (saved >= 0) close(saved);
    rtcReleaseDevice(device);
    return -1;
  }
  fflush(stdout);
  int redirected = dup2(fileno(capture), 1) >= 0;
  double t0 = clock_seconds(CLOCK_MONOTONIC), c0 = eb_cpu_seconds();
  rtcCommitScene(scene);
  *cpu_s = eb_cpu_seconds() - c0;
  *commit_s = clock_seconds(CLOCK_MONOTONIC) - t0;
  fflush(stdout);
  dup2(saved, 1);
  close(saved);
  enum RTCError error = rtcGetDeviceError(device);
  int found = 0;
  char line[512];
  rewind(capture);
  while (redirected && error == RTC_ERROR_NONE && !found &&
         fgets(line, sizeof line, capture) != NULL) {
    /* anywhere in the line: another thread's output without a newline (a test harness's
     * progress dot) may come first */
    const char *at = strstr(line, "BENCHMARK_BUILD ");
    double rate;
    found = at != NULL && sscanf(at, "BENCHMARK_BUILD %lf %lf %lf", build_s, &rate, sah) == 3;
  }
  fclose(capture);
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  if (!redirected) return -2;
  if (error != RTC_ERROR_NONE) return -100 - (int)error;
  return found ? 0 : -3;
}

void eb_free(int h) {
  if (h < 0 || h >= 8 || the_scenes[h].device == NULL) return;
  rtcReleaseScene(the_scenes[h].scene);
  rtcReleaseDevice(the_scenes[h].device);
  the_scenes[h].device = NULL;
  the_scenes[h].scene = NULL;
  release_slot(h);
}

static void init_ray(struct RTCRay *r, const float *p) {
  r->org_x = p[0]; r->org_y = p[1]; r->org_z = p[2]; r->tnear = 0.0f;
  r->dir_x = p[3]; r->dir_y = p[4]; r->dir_z = p[5]; r->time = 0.0f;
  r->tfar = __builtin_inff(); r->mask = 0xFFFFFFFFu; r->id = 0; r->flags = 0;
}

uint64_t eb_intersect1(int h, const float *rays, size_t n) {
  RTCScene scene = the_scenes[h].scene;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  uint64_t hits = 0;
  for (size_t i = 0; i < n; i++) {
    struct RTCRayHit rh;
    init_ray(&rh.ray, rays + 6 * i);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene, &ctx, &rh);
    hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
  }
  return hits;
}

uint64_t eb_occluded1(int h, const float *rays, size_t n) {
  RTCScene scene = the_scenes[h].scene;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  uint64_t hits = 0;
  for (size_t i = 0; i < n; i++) {
    struct RTCRay r;
    init_ray(&r, rays + 6 * i);
    rtcOccluded1(scene, &ctx, &r);
    hits += r.tfar < 0.0f;
  }
  return hits;
}

static int fill16(struct RTCRay16 *r, int valid[16], const float *rays, size_t i, size_t n) {
  int live = 0;
  for (int k = 0; k < 16; k++) {
    size_t j = i + (size_t)k;
    const float *p = rays + 6 * (j < n ? j : i);
    valid[k] = j < n ? -1 : 0;
    live += j < n;
    r->org_x[k] = p[0]; r->org_y[k] = p[1]; r->org_z[k] = p[2]; r->tnear[k] = 0.0f;
    r->dir_x[k] = p[3]; r->dir_y[k] = p[4]; r->dir_z[k] = p[5]; r->time[k] = 0.0f;
    r->tfar[k] = __builtin_inff(); r->mask[k] = 0xFFFFFFFFu; r->id[k] = 0; r->flags[k] = 0;
  }
  return live;
}

/* coherent != 0 sets RTC_INTERSECT_CONTEXT_FLAG_COHERENT (for tiles of primary rays) */
uint64_t eb_intersect16(int h, const float *rays, size_t n, int coherent) {
  RTCScene scene = the_scenes[h].scene;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (coherent) ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  uint64_t hits = 0;
  struct RTCRayHit16 rh;
  /* Embree requires the mask 64-byte aligned (it is read as one vector) */
  _Alignas(64) int valid[16];
  for (size_t i = 0; i < n; i += 16) {
    int live = fill16(&rh.ray, valid, rays, i, n);
    for (int k = 0; k < 16; k++) {
      rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect16(valid, scene, &ctx, &rh);
    for (int k = 0; k < live; k++) hits += rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
  }
  return hits;
}

uint64_t eb_occluded16(int h, const float *rays, size_t n, int coherent) {
  RTCScene scene = the_scenes[h].scene;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (coherent) ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  uint64_t hits = 0;
  struct RTCRay16 r;
  _Alignas(64) int valid[16];
  for (size_t i = 0; i < n; i += 16) {
    int live = fill16(&r, valid, rays, i, n);
    rtcOccluded16(valid, scene, &ctx, &r);
    for (int k = 0; k < live; k++) hits += r.tfar[k] < 0.0f;
  }
  return hits;
}
