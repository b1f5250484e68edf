// Native checks of the tracer internals (also run under ASan + UBSan by `make sanitize`): BVH and BVH4
// invariants, binary and 4-wide traversal against brute force, render determinism across thread counts, exactness of the adaptive modes
// at full rate, zero-separation stereo.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <vector>

#include "sim_core/render.h"
#include "sim_core/scene.h"
#include "sim_core/stereo.h"

#include "check.h"

using namespace sim_core;


namespace {

// A bumpy closed sphere (UV-sphere with jittered radii) plus a ground quad: some depth complexity.
void make_mesh(std::vector<float>* pos, std::vector<std::uint32_t>* tri, std::vector<std::uint32_t>* obj) {
  const int nu = 24, nv = 12;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> jitter(0.9f, 1.1f);
  pos->clear(); tri->clear(); obj->clear();
  pos->insert(pos->end(), {0.f, 0.f, 2.f});  // north pole
  for (int v = 1; v < nv; ++v)
    for (int u = 0; u < nu; ++u) {
      const float th = kPi * v / nv, ph = 2 * kPi * u / nu, r = jitter(rng);
      pos->insert(pos->end(), {r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph), 1.f + r * std::cos(th)});
    }
  pos->insert(pos->end(), {0.f, 0.f, 0.f});  // south pole
  const std::uint32_t south = static_cast<std::uint32_t>(pos->size() / 3 - 1);
  auto ring = [&](int v, int u) { return static_cast<std::uint32_t>(1 + (v - 1) * nu + (u % nu)); };
  for (int u = 0; u < nu; ++u) tri->insert(tri->end(), {0u, ring(1, u), ring(1, u + 1)});
  for (int v = 1; v + 1 < nv; ++v)
    for (int u = 0; u < nu; ++u) {
      tri->insert(tri->end(), {ring(v, u), ring(v + 1, u), ring(v + 1, u + 1)});
      tri->insert(tri->end(), {ring(v, u), ring(v + 1, u + 1), ring(v, u + 1)});
    }
  for (int u = 0; u < nu; ++u) tri->insert(tri->end(), {ring(nv - 1, u), south, ring(nv - 1, u + 1)});
  obj->assign(tri->size() / 3, 0u);
  const std::uint32_t g = static_cast<std::uint32_t>(pos->size() / 3);
  pos->insert(pos->end(), {-6.f, -6.f, 0.f, 6.f, -6.f, 0.f, 6.f, 6.f, 0.f, -6.f, 6.f, 0.f});
  tri->insert(tri->end(), {g, g + 1, g + 2, g, g + 2, g + 3});
  obj->insert(obj->end(), {1u, 1u});
}

Scene make_scene() {
  std::vector<float> pos;
  std::vector<std::uint32_t> tri, obj;
  make_mesh(&pos, &tri, &obj);
  const std::size_t nt = tri.size() / 3;
  std::vector<std::int64_t> ids(nt);
  for (std::size_t i = 0; i < nt; ++i) ids[i] = static_cast<std::int64_t>(i);
  std::vector<std::uint32_t> mats(nt, 0u);
  mats[nt - 1] = mats[nt - 2] = 1u;
  const float materials[2 * kMaterialFields] = {0.9f, 0.8f, 0.7f, 1.f, 0.2f, 0.f, 1.5f, 0.f, 0.f, 0.f,
                                                0.5f, 0.5f, 0.5f, 0.f, 0.9f, 0.f, 1.5f, 0.f, 0.f, 0.f};
  const float lights[kLightFields] = {0.f, 3.f, -2.f, 5.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 40.f, 0.3f, 0.7f};
  return Scene(pos.data(), pos.size() / 3, tri.data(), nt, ids.data(), nullptr, mats.data(), obj.data(),
               materials, 2, lights, 1, Environment(Vec3(0.3f, 0.3f, 0.35f)));
}

void check_bvh(const Scene& s) {
  const Bvh& b = s.bvh();
  std::vector<int> seen(s.triangle_count(), 0);
  for (std::size_t i = 0; i < b.nodes.size(); ++i) {
    if (i == 1) continue;  // padding
    const BvhNode& n = b.nodes[i];
    if (n.count == 0) {
      CHECK(n.first % 2 == 0 && n.first + 1 < b.nodes.size());
      for (int c = 0; c < 2; ++c) {
        const BvhNode& ch = b.nodes[n.first + c];
        for (int a = 0; a < 3; ++a) CHECK(ch.lo[a] >= n.lo[a] && ch.hi[a] <= n.hi[a]);
      }
    } else {
      CHECK(n.count <= 4);
      for (std::uint32_t t = n.first; t < n.first + n.count; ++t) {
        ++seen[t];
        for (int k = 0; k < 9; ++k) CHECK(s.tri(t).v[k] >= n.lo[k % 3] && s.tri(t).v[k] <= n.hi[k % 3]);
      }
    }
  }
  for (int c : seen) CHECK(c == 1);
}

// Walks the 4-wide BVH: every triangle in exactly one leaf block, blocks hold the records' vertices,
// every child box holds its subtree's triangles, empty slots are inverted boxes.
void check_bvh4_node(const Scene& s, std::uint32_t idx, const float* box_lo, const float* box_hi,
                     std::vector<int>* seen, int level) {
  const Bvh4& b = s.bvh4();
  CHECK(idx < b.nodes.size() && level <= 64);
  if (idx >= b.nodes.size() || level > 64) return;
  const Bvh4Node& n = b.nodes[idx];
  for (int i = 0; i < 4; ++i) {
    const float lo[3] = {n.box[0][i], n.box[2][i], n.box[4][i]}, hi[3] = {n.box[1][i], n.box[3][i], n.box[5][i]};
    if (n.count[i] == 0 && lo[0] > hi[0]) {  // empty slot
      for (int a = 0; a < 3; ++a) CHECK(std::isinf(lo[a]) && lo[a] > 0 && std::isinf(hi[a]) && hi[a] < 0);
      continue;
    }
    if (box_lo)
      for (int a = 0; a < 3; ++a) CHECK(lo[a] >= box_lo[a] && hi[a] <= box_hi[a]);
    if (n.count[i] == 0) {
      check_bvh4_node(s, n.child[i], lo, hi, seen, level + 1);
      continue;
    }
    std::uint32_t left = n.count[i];
    for (std::uint32_t k = n.child[i]; left > 0; ++k) {
      CHECK(k < b.blocks.size());
      if (k >= b.blocks.size()) return;
      const TriBlock4& blk = b.blocks[k];
      CHECK(blk.count == std::min(4u, left));
      for (std::uint32_t l = 0; l < blk.count; ++l) {
        const TriRecord& t = s.tri(blk.first + l);
        ++(*seen)[blk.first + l];
        for (int v = 0; v < 3; ++v)
          for (int a = 0; a < 3; ++a) {
            CHECK(blk.v[v][a][l] == t.v[3 * v + a]);
            CHECK(t.v[3 * v + a] >= lo[a] && t.v[3 * v + a] <= hi[a]);
          }
      }
      left -= blk.count;
    }
  }
}

void check_bvh4(const Scene& s) {
  std::vector<int> seen(s.triangle_count(), 0);
  check_bvh4_node(s, 0, nullptr, nullptr, &seen, 0);
  for (int c : seen) CHECK(c == 1);
}

// The parallel build gives the same tree, bit for bit, for any thread count (40K triangles: enough for
// the builder to fork its top levels).
void check_parallel_build_identical() {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-10.f, 10.f), e(-0.3f, 0.3f);
  std::vector<TriRecord> base(40000);
  for (std::size_t i = 0; i < base.size(); ++i) {
    const float cx = u(rng), cy = u(rng), cz = u(rng) * (i % 3 == 0 ? 0.1f : 1.f);  // clustered slabs
    for (int k = 0; k < 3; ++k) {
      base[i].v[3 * k] = cx + e(rng);
      base[i].v[3 * k + 1] = cy + e(rng);
      base[i].v[3 * k + 2] = cz + e(rng);
    }
    base[i].prim = static_cast<std::uint32_t>(i);
    base[i].material = base[i].object = 0;
  }
  std::vector<BvhNode> ref_nodes;
  std::vector<std::uint32_t> ref_order;
  int ref_depth = 0, ref_leaves = 0;
  for (int threads : {1, 2, 3, 4, 8}) {
    std::vector<TriRecord> tris = base;
    std::vector<std::uint32_t> order;
    BvhBuildOptions opt;
    opt.threads = threads;
    const Bvh b = build_bvh(tris, &order, opt);
    if (threads == 1) {
      ref_nodes = b.nodes; ref_order = order; ref_depth = b.depth; ref_leaves = b.leaf_count;
      continue;
    }
    CHECK(b.nodes.size() == ref_nodes.size() && order == ref_order);
    CHECK(b.depth == ref_depth && b.leaf_count == ref_leaves);
    CHECK(b.nodes.size() == ref_nodes.size() &&
          std::memcmp(b.nodes.data(), ref_nodes.data(), b.nodes.size() * sizeof(BvhNode)) == 0);
  }
}

void check_against_brute_force(const Scene& s) {
  std::mt19937 rng(3);
  std::normal_distribution<float> nd;
  int mismatches = 0;
  for (int i = 0; i < 20000; ++i) {
    Ray r;
    r.origin = Vec3(nd(rng) * 3.f, nd(rng) * 3.f, 1.f + nd(rng) * 3.f);
    r.dir = normalize(Vec3(nd(rng), nd(rng), nd(rng)));
    const Hit h = s.closest(r);
    float best = kInf;
    const PreparedRay pr(r);
    for (std::uint32_t t = 0; t < s.triangle_count(); ++t) {
      float tt, b0, b1, b2;
      bool cmp = false;
      if (intersect_triangle(s.tri(t), pr, 0.f, best, &tt, &b0, &b1, &b2, &cmp)) best = tt;
    }
    if (h.t != best) ++mismatches;
    const Hit h2 = s.closest_binary(r);
    if (h2.t != best || h2.hit() != h.hit()) ++mismatches;
    if (h.hit()) {  // barycentrics of the SIMD lane equal the scalar test's
      float tt, b0, b1, b2;
      bool cmp = false;
      CHECK(intersect_triangle(s.tri(h.tri), pr, 0.f, kInf, &tt, &b0, &b1, &b2, &cmp) && tt == h.t);
      CHECK(b0 == h.b0 && b1 == h.b1 && b2 == h.b2);
    }
    NullRecorder rec;
    const Ray shadow{r.origin, r.dir, 0.f, best};
    CHECK(!s.occluded(shadow, rec) || best < kInf);
  }
  CHECK(mismatches == 0);
}

bool same(const RenderOutput& a, const RenderOutput& b) {
  return a.fb.color == b.fb.color && a.fb.depth == b.fb.depth && a.counters.rays_total == b.counters.rays_total &&
         a.histogram == b.histogram;
}

void check_render(const Scene& s) {
  Camera cam;
  cam.position = Vec3(0.f, -6.f, 2.5f);
  cam.forward = normalize(Vec3(0.f, 6.f, -1.5f));
  cam.right = normalize(cross(cam.forward, Vec3(0.f, 0.f, 1.f)));
  cam.up = cross(cam.right, cam.forward);
  cam.vfov = 0.8f;
  cam.width = 40;
  cam.height = 30;
  const CacheConfig cache{16384, 64, 4};
  RenderSettings st;
  st.shadow_samples = 4;
  st.ao_samples = 2;
  st.tile_size = 8;
  for (int mode = 0; mode < 4; ++mode) {
    st.mode = static_cast<SamplingMode>(mode);
    const RenderOutput a = render_frame(s, cam, st, 1, nullptr, cache);
    const RenderOutput b = render_frame(s, cam, st, 2, nullptr, cache);
    CHECK(same(a, b));
    for (float c : a.fb.color) CHECK(std::isfinite(c) && c >= 0.f);
  }
  RenderSettings ref = st;
  ref.mode = SamplingMode::kOneSpp;
  RenderSettings under = st;
  under.mode = SamplingMode::kUndersample;
  under.block = 3;
  under.normal_threshold_deg = -1.f;
  CHECK(render_frame(s, cam, ref, 2, nullptr, cache).fb.color == render_frame(s, cam, under, 2, nullptr, cache).fb.color);
  const StereoOutput so = render_stereo(s, cam, cam, ref, 2, nullptr, cache);
  CHECK(so.reuse_ratio == 1.0);
  CHECK(so.left.fb.color == so.right.fb.color);
  // Multi-rate: a second frame uses the first frame's state.
  RenderSettings mr = st;
  mr.mode = SamplingMode::kUndersample;
  mr.multirate = true;
  const RenderOutput f0 = render_frame(s, cam, mr, 2, nullptr, cache);
  const RenderOutput f1 = render_frame(s, cam, mr, 2, &f0.multirate, cache);
  CHECK(f1.multirate.block.size() == f0.multirate.block.size());
}

}  // namespace

int main() {
  const Scene s = make_scene();
  check_bvh(s);
  check_bvh4(s);
  check_parallel_build_identical();
  check_against_brute_force(s);
  check_render(s);
  return check_exit_code();
}
