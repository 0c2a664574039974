#include "sim/placement.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include "common/number_text.h"
#include "sim/parallel.h"
#include "sim/particles.h"
#include "sim/winding_field.h"

namespace collido::sim {

// Largest inlet radius in particle spacings: a disc of about 3 million slots.
constexpr double kMaxInletSlots = 1000;
// Half-angle of an inlet's spray, as its tangent (about 3 degrees).
constexpr double kInletSpread = 0.05;

const char* to_string(PlacementKind k) {
  return k == PlacementKind::kFill ? "fill" : k == PlacementKind::kPour ? "pour" : "jet";
}

bool parse_placement_kind(const std::string& s, PlacementKind* out) {
  if (s == "fill") return *out = PlacementKind::kFill, true;
  if (s == "pour") return *out = PlacementKind::kPour, true;
  if (s == "jet") return *out = PlacementKind::kJet, true;
  return false;
}

namespace {

bool finite3(Vec3d v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Whether fill sites lie inside a closed wall, with one winding number per
// connected group of sites instead of one per site (each costs a pass over
// every triangle: 38,000 sites over an 83,750-triangle mesh took 70 s). Two
// neighbouring sites whose clear balls (no wall within them) together reach
// across the gap between them are joined by a segment the wall does not cross,
// so they lie on the same side of it. Groups are merged across layers with a
// union-find over group ids, each holding its side once known.
// Disjoint sets (union-find with path halving): a layer's sites, and the groups.
struct DisjointSets {
  std::vector<uint32_t> parent;
  explicit DisjointSets(size_t n = 0) : parent(n) {
    for (size_t i = 0; i < n; ++i) parent[i] = uint32_t(i);
  }
  uint32_t add() {
    parent.push_back(uint32_t(parent.size()));
    return parent.back();
  }
  uint32_t find(uint32_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  }
  // Joins a's set into b's; returns b's root.
  uint32_t join(uint32_t a, uint32_t b) {
    a = find(a), b = find(b);
    parent[a] = b;
    return b;
  }
};

// Whether a point of this generalized winding number lies inside the wall as a
// vessel holds it: 1/2 or more in magnitude (a vessel wound inward, as other DEM codes
// export them, has w = -1 inside).
bool holds(double winding) { return std::fabs(winding) >= 0.5; }

// Solid angles an open wall's sites may sum (each site's share of the winding
// field's work, measured at the probes), about 10 s of plain sums; a closed
// wall's rays (Hollows) are held to it too.
constexpr double kOpenSideWork = 4e8;
constexpr int kEnclosureProbes = 4;  // a side: 4^3 probes of the box

// Whether pred holds at one of kEnclosureProbes^3 probes spread through [lo, hi].
template <class Pred>
bool some_probe(Vec3d lo, Vec3d hi, Pred&& pred) {
  constexpr int n = kEnclosureProbes;
  const Vec3d step = (hi - lo) * (1.0 / n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        if (pred(lo + Vec3d{(i + 0.5) * step.x, (j + 0.5) * step.y, (k + 0.5) * step.z}))
          return true;
  return false;
}

// Where the line p + s dir meets triangle t of the wall: s (in lengths of dir;
// negative behind p), or -1 where it misses the triangle or runs along its
// plane (Moller and Trumbore, in double).
double ray_distance(const TriangleMesh& wall, size_t t, Vec3d p, Vec3d dir) {
  const Vec3d a = wall.corner(t, 0), e1 = wall.corner(t, 1) - a, e2 = wall.corner(t, 2) - a;
  const Vec3d q = cross(dir, e2);
  const double det = dot(e1, q);
  if (std::fabs(det) < 1e-300) return -1;
  const double inv = 1.0 / det;
  const Vec3d o = p - a;
  const double u = dot(o, q) * inv;
  if (u < 0 || u > 1) return -1;
  const Vec3d w = cross(o, e1);
  const double v = dot(dir, w) * inv;
  if (v < 0 || u + v > 1) return -1;
  return dot(e2, w) * inv;
}

// Whether the ray from p along dir crosses triangle t of the wall.
bool ray_crosses(const TriangleMesh& wall, size_t t, Vec3d p, Vec3d dir) {
  return ray_distance(wall, t, p, dir) > 0;
}

// Where a closed wall holds particles. Inside it, for a shell (a box, a ball, a
// drum, the paper's wall1, and a solid standing in one: an obstacle), or in its
// hollows, for a solid modelled with its wall's thickness as CAD and 3D
// printing export a cup: its inside is the cup's material, its hollow lies
// outside it, enclosed from below and all around. A hollow lies outside every
// connected piece of the wall (inside a block that stands in a box, the
// block's winding cancels the box's, but the box holds it: an obstacle, not a
// hollow), and rays from it down (along gravity) and four ways across all meet
// the wall. A closed wall with a hollow among the probes of the region
// (some_probe) is a solid; one without is a shell (a plate's holes are open below,
// so a plate stays a shell, its inside the only room in its box), unless no
// probe lies inside the wall either: a region over a solid takes the room
// outside it (a fill dropped onto a plate).
enum class ClosedWallHolds { kInside, kHollows, kOutside };
class Hollows {
 public:
  // field: the open wall's winding numbers (null for a closed wall, or none).
  Hollows(const TriangleMesh& wall, const WindingField* field, bool closed, Vec3d down)
      : wall_(wall), field_(field), closed_(closed) {
    // The rays lean a little off the axes, so that none runs along a face or
    // through an edge of an axis-aligned wall.
    const Vec3d d = down * (1.0 / length(down));
    Vec3d u = cross(d, std::fabs(d.x) < 0.9 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0});
    u = u * (1.0 / length(u));
    const Vec3d w = cross(d, u);
    rays_ = {d + u * 0.0123 + w * 0.0217, u + w * 0.0131 + d * 0.0079,
             u * -1.0 + w * 0.0173 + d * 0.0061, w + u * 0.0157 + d * 0.0089,
             w * -1.0 + u * 0.0113 + d * 0.0071};
    // Connected pieces: triangles that share corners.
    DisjointSets corners(wall.vertices.size());
    for (const auto& t : wall.triangles) corners.join(t[0], t[1]), corners.join(t[0], t[2]);
    std::vector<int> piece_of_corner(wall.vertices.size(), -1);
    piece_.reserve(wall.triangles.size());
    for (const auto& t : wall.triangles) {
      int& k = piece_of_corner[corners.find(t[0])];
      if (k < 0) k = int(pieces_++);
      piece_.push_back(uint32_t(k));
    }
  }
  // Work of one look: five rays over every triangle (and a winding number, open).
  double work() const { return (closed_ ? 5.0 : 6.0) * double(wall_.triangles.size()); }
  enum class Place { kInPiece, kHollow, kOpen };
  Place place(Vec3d p) const {
    // Inside a piece: on a closed wall an odd count of its crossings along
    // the ray down; on an open one (a solid exported with a seam or a slit
    // left open) a winding number of 1/4 or more (1/2 on a face, 0 clear of
    // a solid). Outside all, a hollow where every ray meets the wall.
    if (!closed_ && field_ && std::fabs(field_->at(p)) >= 0.25) return Place::kInPiece;
    std::vector<uint8_t> odd(pieces_, 0);
    bool met = false;
    for (size_t t = 0; t < wall_.triangles.size(); ++t)
      if (ray_crosses(wall_, t, p, rays_[0])) odd[piece_[t]] ^= 1, met = true;
    if (closed_)
      for (uint8_t o : odd)
        if (o) return Place::kInPiece;
    if (!met) return Place::kOpen;
    for (size_t k = 1; k < rays_.size(); ++k) {
      bool hit = false;
      for (size_t t = 0; t < wall_.triangles.size() && !hit; ++t)
        hit = ray_crosses(wall_, t, p, rays_[k]);
      if (!hit) return Place::kOpen;
    }
    return Place::kHollow;
  }
  bool hollow(Vec3d p) const { return place(p) == Place::kHollow; }
  // A region with a hollow among its probes: the hollows; with none inside a
  // piece either (a region over a solid): the room outside the wall; else
  // (and past kOpenSideWork for the probes) a shell's inside.
  ClosedWallHolds mode(Vec3d lo, Vec3d hi) const {
    constexpr double kProbes = double(kEnclosureProbes) * kEnclosureProbes * kEnclosureProbes;
    if (work() * kProbes > kOpenSideWork) return ClosedWallHolds::kInside;
    bool in_piece = false;
    const bool hollow = some_probe(lo, hi, [&](Vec3d p) {
      const Place at = place(p);
      in_piece |= at == Place::kInPiece;
      return at == Place::kHollow;
    });
    return hollow     ? ClosedWallHolds::kHollows
           : in_piece ? ClosedWallHolds::kInside
                      : ClosedWallHolds::kOutside;
  }

 private:
  const TriangleMesh& wall_;
  const WindingField* field_;
  bool closed_;
  std::vector<Vec3d> rays_;
  std::vector<uint32_t> piece_;  // each triangle's piece
  size_t pieces_ = 0;
};

// Groups of places joined without crossing a closed wall, each on one side of
// it, so each group needs one look at the wall: its winding number (inside or
// out) and, for a solid's hollows, whether it is one. per_place: a hollow's
// enclosure is looked at for each place (a group of a hollow may reach over
// its rim, out of the cup, where a region is taller than the wall).
class SideOfWall {
 public:
  SideOfWall(const TriangleMesh& wall, ClosedWallHolds mode, const Hollows& hollows,
             bool per_place)
      : wall_(wall), mode_(mode), hollows_(hollows), per_place_(per_place) {}
  int new_group() {
    side_.push_back(kUnknown);
    return int(groups_.add());
  }
  void join(int a, int b) {
    const uint8_t side = side_[groups_.find(uint32_t(a))];
    const uint32_t root = groups_.join(uint32_t(a), uint32_t(b));
    if (side_[root] == kUnknown) side_[root] = side;
  }
  bool inside(int g, Vec3d p) {
    const uint32_t root = groups_.find(uint32_t(g));
    if (side_[root] == kUnknown) {
      const bool in_wall = holds(winding_number(wall_, p));  // one a group: the plain sum
      side_[root] = mode_ == ClosedWallHolds::kInside ? (in_wall ? kIn : kOut)
                    : in_wall                          ? kOut
                    : mode_ == ClosedWallHolds::kOutside ? kIn
                    : per_place_                       ? kOutside
                    : hollows_.hollow(p)               ? kIn
                                                       : kOut;
    }
    if (side_[root] == kOutside) return hollows_.hollow(p);
    return side_[root] == kIn;
  }

 private:
  // kOutside: outside the wall, each place's enclosure still to be looked at.
  enum : uint8_t { kUnknown, kIn, kOut, kOutside };
  const TriangleMesh& wall_;
  ClosedWallHolds mode_;
  const Hollows& hollows_;
  bool per_place_;
  DisjointSets groups_;
  std::vector<uint8_t> side_;
};

// Whether an open wall holds some of the box [lo, hi] as a vessel does: its
// winding number reaches 0.6 at one of the probes spread through it (a flat
// wall never passes 1/2; a funnel's middle has about 2/3).
bool encloses_some(const WindingField& wall, Vec3d lo, Vec3d hi, WindingField::Work* work) {
  return some_probe(lo, hi, [&](Vec3d p) { return std::fabs(wall.at(p, work)) >= 0.6; });
}

// Whether the sites of an open (not closed) wall, a cup or a funnel, are told inside from
// outside one by one, by their winding numbers: its winding number is not
// constant between sites the wall does not part (it falls through the
// opening). Only where the wall encloses some of [lo, hi] (an open wall that
// holds nothing, a floor or a plate, keeps every clear site), and only where
// the sites' winding numbers, at the probes' work each, stay within
// kOpenSideWork (past it, every clear site is kept).
bool sites_by_winding(const WindingField& wall, Vec3d lo, Vec3d hi, double sites) {
  const size_t triangles = wall.triangles();
  const double probes = double(kEnclosureProbes) * kEnclosureProbes * kEnclosureProbes;
  // A field that answers by the plain sum (a wall wound every which way): a pass
  // over every triangle a point, the probes' included.
  if (wall.plain() && double(triangles) * (sites + probes) > kOpenSideWork) return false;
  WindingField::Work work;
  if (!encloses_some(wall, lo, hi, &work)) return false;
  // Solid angles a point: the exact ones, the dipoles, and a pass over every
  // triangle for each point the plain sum answered.
  const double per_point = double(work.exact_triangles + work.far_nodes + work.plain * triangles) /
                           double(std::max<uint64_t>(work.points, 1));
  return per_point * sites <= kOpenSideWork;
}

// How the clear places that a fill or the default inlet offers in the box
// [lo, hi] (`places` of them) are told inside the vessel from outside it. A
// closed wall: by groups of clear neighbours, one look a group (SideOfWall;
// the caller joins the groups). An open wall that encloses: each place by
// its winding number (sites_by_winding). An open solid with a hollow (a cup
// exported with a seam left open): each place by its rays, while they stay
// within kOpenSideWork. Any other open wall holds nothing (a floor, a
// plate): every clear place is kept.
class VesselSides {
 public:
  enum class Rule { kGroups, kWinding, kHollows, kEvery };
  VesselSides(const TriangleMesh& wall, Vec3d lo, Vec3d hi, double places, Vec3d down)
      : wall_(wall),
        lo_(lo),
        hi_(hi),
        closed_(is_closed_manifold(wall)),
        field_(closed_ ? kNoWall : wall),
        winding_(!closed_ && sites_by_winding(field_, lo, hi, places)),
        hollows_(closed_ || !winding_ ? wall : kNoWall, closed_ || winding_ ? nullptr : &field_,
                 closed_, down),
        one_by_one_(hollows_.work() * places <= kOpenSideWork) {
    rule_ = closed_    ? Rule::kGroups
            : winding_ ? Rule::kWinding
            : one_by_one_ && hollows_.mode(lo, hi) == ClosedWallHolds::kHollows ? Rule::kHollows
                                                                                : Rule::kEvery;
  }
  VesselSides(const VesselSides&) = delete;  // its groups hold references to it
  Rule rule() const { return rule_; }
  // kGroups: groups for the caller to make and join; where the region has a
  // hollow, its places' enclosures are looked at one by one (one_by_one_).
  SideOfWall groups() const {
    return SideOfWall(wall_, hollows_.mode(lo_, hi_), hollows_, one_by_one_);
  }
  // The other rules: whether clear place p is inside.
  bool inside(Vec3d p) const {
    return rule_ == Rule::kWinding   ? holds(field_.at(p))
           : rule_ == Rule::kHollows ? hollows_.hollow(p)
                                     : true;
  }

 private:
  static inline const TriangleMesh kNoWall{};  // no pieces to find where no ray is cast
  const TriangleMesh& wall_;
  Vec3d lo_, hi_;
  bool closed_;
  // An open wall's winding numbers, many sites' worth. A closed wall's groups
  // need one each, where building the field would cost more (1.7 s for a ball
  // of 1.3 million triangles): none there.
  WindingField field_;
  bool winding_;
  Hollows hollows_;
  bool one_by_one_;
  Rule rule_ = Rule::kEvery;
};

// The lattice starts 1.1 r from the region's faces, so that on a floor at the
// region's bottom the first layer is clear of it and kept (a radius from the
// faces, it touched the floor and fills began a layer up).
double fill_spacing(double r) {
  return 2 * r * 1.05;
}
double fill_margin(double r) {
  return 1.1 * r;
}

}  // namespace

double fill_sites_along(double side, double r_max) {
  const double n = std::floor((side - 2 * fill_margin(r_max)) / fill_spacing(r_max)) + 1;
  return n < 1 ? 0.0 : n;
}

namespace {

// Lattice sites in the region, a layer (fixed z) at a time from the bottom, that
// lie inside the wall (closed, or an open vessel's) and clear of its surface,
// until `count` are found.
Status fill(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
            Vec3d down, SplitMix64& rng, ParticleSet* out, ThreadPool* pool) {
  const Bounds3d box = mesh_bounds(wall);
  const Vec3d lo = pl.has_region ? pl.region_lo : box.lo,
              hi = pl.has_region ? pl.region_hi : box.hi;
  if (!(lo.x < hi.x && lo.y < hi.y && lo.z < hi.z))
    return invalid_argument("placement.region: min must lie below max on every axis");
  const double r = ps.r_max, spacing = fill_spacing(r), jitter = 0.02 * r, margin = fill_margin(r);
  auto sites = [&](double a, double b) {
    return uint64_t(std::min(fill_sites_along(b - a, r), 1e7));
  };
  const uint64_t nx = sites(lo.x, hi.x), ny = sites(lo.y, hi.y), nz = sites(lo.z, hi.z);
  // A layer's sites cost a few hundred bytes each (their positions, the
  // detector's buffers): never more than the fill could use, give or take, so
  // that ten tiny particles in a large box do not ask for gigabytes.
  const uint64_t most_sites =
      std::min<uint64_t>(uint64_t(1) << 26, std::max<uint64_t>(uint64_t(1) << 20, 64 * ps.count));
  if (nx * ny > most_sites)
    return invalid_argument("placement.region: a layer of " + std::to_string(nx * ny) +
                            " sites is too large for " + std::to_string(ps.count) +
                            " particles (at most " + std::to_string(most_sites) +
                            "); give a smaller region or larger particles");
  // An open vessel (a cup, a funnel) has no inside by parity: a site is
  // inside where its own winding number says so. A fill's box region holds a
  // cup's corners, outside the cup: 30 of 300 particles were placed there and
  // fell away.
  const VesselSides sides(wall, lo, hi, double(ps.count), down);
  const bool closed = sides.rule() == VesselSides::Rule::kGroups;
  // The wall's own detector finds sites that would start touching it; on a
  // closed wall a second look at a larger radius finds the sites clear enough
  // to join their neighbours (SideOfWall).
  const double clear = r * 1.05, wide = r * 1.1;
  DetectConfig dc;
  dc.r_max = closed ? wide : clear;
  dc.time_stages = false;
  // Below kFillTreeBelow particles a tree over the wall's own triangles: bin's
  // grid at the particles' size costs its build whatever the sites (a fill
  // of 5,000 into wall1 at r = 0.5: `run` 0.44 -> 0.35 s, and a start
  // preview the new-job form asks for 68-83 -> 12-14 ms); at 200,000 bin's
  // faster queries paid for it (`run` 1.13 against 1.18-1.21 s). Both are
  // exact: the same sites either way.
  constexpr uint64_t kFillTreeBelow = 50000;
  if (ps.count < kFillTreeBelow) dc.method = Method::kBvh;
  auto detector = Detector::create(wall, dc, std::max<uint64_t>(nx * ny, 1));
  if (!detector) return detector.status();
  // Runs the detector on the layer at radius `radius`: per site, touching or not.
  auto touches = [&](Particles& layer, double radius, std::vector<uint32_t>* counts) -> Status {
    std::fill(layer.r.begin(), layer.r.end(), radius);
    if (Status s = (*detector)->set_particles(layer); !s) return s;
    DetectResult found;
    (*detector)->set_frame_options(false, false);
    if (Status s = (*detector)->detect(&found); !s) return s;
    *counts = std::move(found.counts);
    return Status::ok();
  };
  std::optional<SideOfWall> side;
  if (closed) side.emplace(sides.groups());
  const size_t per_layer = size_t(nx * ny);
  std::vector<int> group(per_layer, -1), last_group(per_layer, -1);  // -1: not clear
  std::vector<double> reach(per_layer, 0), last_reach(per_layer, 0);
  Particles last;
  out->resize(0);
  // Layers are searched until the count is placed, each costing two
  // detections: a region that reaches far beyond the wall (millions of empty
  // layers) would search for days. Bounded by what a fill of a few per cent
  // of its region would look at.
  const uint64_t most_searched = std::max<uint64_t>(uint64_t(1) << 26, 256 * ps.count);
  uint64_t searched = 0;
  for (uint64_t k = 0; k < nz && out->size() < ps.count; ++k) {
    if (searched > most_searched)
      return invalid_argument(
          "placement: the region's first " + std::to_string(searched) + " places held only " +
          std::to_string(out->size()) + " of the " + std::to_string(ps.count) +
          " particles: it lies mostly outside the wall; give a region around the wall's inside");
    searched += per_layer;
    Particles layer;
    for (uint64_t j = 0; j < ny; ++j)
      for (uint64_t i = 0; i < nx; ++i) {
        layer.x.push_back(lo.x + margin + i * spacing + rng.uniform(-jitter, jitter));
        layer.y.push_back(lo.y + margin + j * spacing + rng.uniform(-jitter, jitter));
        layer.z.push_back(lo.z + margin + k * spacing + rng.uniform(-jitter, jitter));
        layer.r.push_back(clear);
      }
    std::vector<uint32_t> touching, touching_wide;
    if (Status s = touches(layer, clear, &touching); !s) return s;
    if (closed) {
      if (Status s = touches(layer, wide, &touching_wide); !s) return s;
      // How far from each clear site the wall surely is not; then the groups.
      for (size_t s = 0; s < per_layer; ++s)
        reach[s] = touching[s] ? 0 : touching_wide[s] ? clear : wide;
      auto site = [&](const Particles& p, size_t s) { return Vec3d{p.x[s], p.y[s], p.z[s]}; };
      auto joined = [&](Vec3d a, double ra, Vec3d b, double rb) {
        return ra > 0 && rb > 0 && length(a - b) < ra + rb;
      };
      DisjointSets sets(per_layer);
      for (size_t s = 0; s < per_layer; ++s) {
        const size_t i = s % nx;
        if (i > 0 && joined(site(layer, s), reach[s], site(layer, s - 1), reach[s - 1]))
          sets.join(uint32_t(s), uint32_t(s - 1));
        if (s >= nx && joined(site(layer, s), reach[s], site(layer, s - nx), reach[s - nx]))
          sets.join(uint32_t(s), uint32_t(s - nx));
      }
      std::fill(group.begin(), group.end(), -1);
      std::vector<int> of_root(per_layer, -1);
      for (size_t s = 0; s < per_layer; ++s) {
        if (!(reach[s] > 0)) continue;
        int& g = of_root[sets.find(uint32_t(s))];
        if (g < 0) g = side->new_group();
        group[s] = g;
        if (k > 0 && last_group[s] >= 0 && joined(site(layer, s), reach[s], site(last, s), last_reach[s]))
          side->join(last_group[s], g);
      }
    }
    // An open wall's places are looked at one by one (a winding number from
    // the field, or rays over every triangle): a chunk of the layer's clear places
    // at a time, on the pool when there is one, small enough that the last
    // layer looks at few places it does not take.
    const bool one_by_one = !closed && sides.rule() != VesselSides::Rule::kEvery;
    const size_t chunk = 64 * size_t(pool ? pool->size() : 1);
    std::vector<uint8_t> in(one_by_one ? layer.size() : 0, 0);
    size_t looked = 0;  // places [0, looked) of the layer have `in` decided
    auto look = [&](size_t begin, size_t end) {
      for (size_t t = begin; t < end; ++t)
        if (!touching[t]) in[t] = sides.inside(Vec3d{layer.x[t], layer.y[t], layer.z[t]});
    };
    for (size_t s = 0; s < layer.size() && out->size() < ps.count; ++s) {
      if (touching[s]) continue;
      const Vec3d p{layer.x[s], layer.y[s], layer.z[s]};
      if (one_by_one && s >= looked) {
        const size_t end = std::min(layer.size(), s + chunk);
        if (pool)
          pool->run_chunks(end - s, 1, [&](size_t b, size_t e) { look(s + b, s + e); });
        else
          look(s, end);
        looked = end;
      }
      if (closed ? !side->inside(group[s], p) : one_by_one && !in[s]) continue;
      const size_t n = out->size();
      out->resize(n + 1);
      out->x[n] = layer.x[s], out->y[n] = layer.y[s], out->z[n] = layer.z[s];
      out->vx[n] = pl.velocity.x, out->vy[n] = pl.velocity.y, out->vz[n] = pl.velocity.z;
    }
    if (closed) {
      std::swap(group, last_group);
      std::swap(reach, last_reach);
      last = std::move(layer);
    }
  }
  if (out->size() < ps.count)
    return invalid_argument("placement: the region holds only " + std::to_string(out->size()) +
                            " of the " + std::to_string(ps.count) + " particles of radius " +
                            number_text(r) + " m; use fewer or smaller particles, or a pour");
  return Status::ok();
}

// A hexagonal lattice of slots across the inlet disc, a spacing s = 2.2 r apart.
// Each slot releases a particle every tau, the time a particle takes to move s
// on, so two particles of one slot never overlap; different slots are s apart
// across. The inlet's capacity is slots / tau: a rate above it is refused
// (no arrangement of a disc's particles delivers more at that speed).
struct InletLayout {
  Vec3d v, centre;
  Vec3d u, w;               // unit vectors across the inlet
  std::vector<Vec3d> disc;  // slot offsets from the centre
  double tau = 0;           // s between two releases of one slot
};

// Drops the slots whose particle would start in the wall or too near it to
// leave cleanly (the wall's own detector at 1.1 r: the jitter, and room for
// the first step), and, for the default inlet (3 r under the top of the
// wall's box, meant to pour into the vessel), those outside a wall that holds
// particles: a closed wall, or an open one that encloses (sites_by_winding),
// as for a fill's sites. A disc wider than a
// ball's top reached past its side, and a disc under a plate's top lay across
// its holes: particles were released into the wall and thrown off at hundreds
// of metres a second (40 of 300 escaped a pour into a ball). On a closed wall
// two clear neighbours (2.2 r apart, each clear for 1.1 r) lie on one side of
// it, so each group of them needs one winding number. lattice: each slot's (i, j).
Status drop_blocked_slots(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
                          const Bounds3d& box, Vec3d centre, Vec3d down, std::vector<Vec3d>* disc,
                          const std::vector<std::pair<int, int>>& lattice) {
  const double r = ps.r_max;
  DetectConfig dc;
  dc.r_max = 1.1 * r;
  dc.time_stages = false;
  // A tree over the wall's own triangles: a few hundred slots are asked once,
  // and `bin`'s grid at the particles' size cost most of a prediction
  // (wall1 at r = 0.5: 68 ms of the 88 every POST /predict took).
  dc.method = Method::kBvh;
  auto detector = Detector::create(wall, dc, disc->size());
  if (!detector) return detector.status();
  Particles slots;
  for (const Vec3d& d : *disc) {
    const Vec3d p = centre + d;
    slots.x.push_back(p.x), slots.y.push_back(p.y), slots.z.push_back(p.z);
    slots.r.push_back(dc.r_max);
  }
  if (Status st = (*detector)->set_particles(slots); !st) return st;
  (*detector)->set_frame_options(false, false);
  DetectResult found;
  if (Status st = (*detector)->detect(&found); !st) return st;
  const size_t n = disc->size();
  std::vector<bool> inside(n, true);
  // An inlet the scene places may pour from anywhere; the default one pours into the vessel.
  std::optional<VesselSides> sides;
  if (!pl.has_inlet) sides.emplace(wall, box.lo, box.hi, double(n), down);
  if (sides && sides->rule() == VesselSides::Rule::kGroups) {
    // Clear neighbours joined, as a fill's sites (SideOfWall): along a row, and to
    // the two nearest of the next row (rows alternate by half a spacing; an odd
    // row is shifted to +x).
    int lo_i = 0, hi_i = 0, lo_j = 0, hi_j = 0;
    for (const auto& [i, j] : lattice) {
      lo_i = std::min(lo_i, i), hi_i = std::max(hi_i, i);
      lo_j = std::min(lo_j, j), hi_j = std::max(hi_j, j);
    }
    const size_t width = size_t(hi_i - lo_i + 1);
    std::vector<int> group_at(width * size_t(hi_j - lo_j + 1), -1);
    auto group = [&](int i, int j) -> int {
      if (i < lo_i || i > hi_i || j < lo_j || j > hi_j) return -1;
      return group_at[size_t(j - lo_j) * width + size_t(i - lo_i)];
    };
    SideOfWall side = sides->groups();
    for (size_t k = 0; k < n; ++k)
      if (found.counts[k] == 0)
        group_at[size_t(lattice[k].second - lo_j) * width + size_t(lattice[k].first - lo_i)] =
            side.new_group();
    for (size_t k = 0; k < n; ++k) {
      const auto [i, j] = lattice[k];
      const int g = group(i, j), up = (j & 1) ? i + 1 : i - 1;  // the next row's other nearest
      if (g < 0) continue;
      for (const int m : {group(i + 1, j), group(i, j + 1), group(up, j + 1)})
        if (m >= 0) side.join(m, g);
    }
    for (size_t k = 0; k < n; ++k)
      if (found.counts[k] == 0) inside[k] = side.inside(group(lattice[k].first, lattice[k].second),
                                                        centre + (*disc)[k]);
  } else if (sides) {
    for (size_t k = 0; k < n; ++k)
      if (found.counts[k] == 0) inside[k] = sides->inside(centre + (*disc)[k]);
  }
  std::vector<Vec3d> kept;
  for (size_t k = 0; k < n; ++k)
    if (found.counts[k] == 0 && inside[k]) kept.push_back((*disc)[k]);
  disc->swap(kept);
  return Status::ok();
}

Status inlet_layout(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
                    Vec3d gravity, InletLayout* out) {
  const Bounds3d box = mesh_bounds(wall);
  const double r = ps.r_max, s = 2.2 * r;
  Vec3d v = pl.velocity;
  const double g = length(gravity);
  if (pl.kind == PlacementKind::kJet && !(length(v) > 0))
    return invalid_argument("placement.velocity: a jet needs a non-zero velocity");
  if (pl.kind == PlacementKind::kPour && !(length(v) > 0)) {
    if (!(g > 0))
      return invalid_argument("placement.velocity: a pour without gravity needs a velocity");
    v = gravity * (1.0 / g);  // 1 m/s along gravity
  }
  const double v0 = length(v);
  const Vec3d dir = v * (1.0 / v0);
  const Vec3d centre =
      pl.has_inlet ? pl.inlet : Vec3d{box.center().x, box.center().y, box.hi.z - 3 * r};
  const double radius =
      pl.inlet_radius > 0 ? pl.inlet_radius : std::min(box.extent().x, box.extent().y) / 3;
  // Two unit vectors across the inlet.
  const Vec3d t = std::fabs(dir.x) < 0.9 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0};
  Vec3d u = cross(dir, t);
  u = u * (1.0 / length(u));
  const Vec3d w = cross(dir, u);
  // Slots across the inlet's radius: bounded before the cast (a huge inlet
  // for tiny particles would overflow int and fill memory with the disc).
  const double across = std::floor(radius / s);
  if (!(across <= kMaxInletSlots))
    return invalid_argument("placement.inlet_radius: " + number_text(radius) + " m is more than " +
                            number_text(kMaxInletSlots) + " particle spacings (" +
                            number_text(s) + " m) across");
  std::vector<Vec3d>& disc = out->disc;
  disc.clear();
  std::vector<std::pair<int, int>> lattice;
  const int n = int(across) + 1;
  const double row = s * std::sqrt(3.0) / 2;
  const int rows = int(std::floor(radius / row));
  for (int j = -rows; j <= rows; ++j)
    for (int i = -n; i <= n; ++i) {
      const double a = (i + ((j & 1) ? 0.5 : 0.0)) * s, b = j * row;
      if (std::sqrt(a * a + b * b) <= radius - r) {
        disc.push_back(u * a + w * b);
        lattice.emplace_back(i, j);
      }
    }
  if (disc.empty())
    return invalid_argument("placement.inlet_radius: " + number_text(radius) +
                            " m holds no particle of radius " + number_text(r) + " m");
  const Vec3d down = g > 0 ? gravity : dir;
  if (Status st = drop_blocked_slots(wall, ps, pl, box, centre, down, &disc, lattice); !st)
    return st;
  if (disc.empty())
    return invalid_argument(
        "placement: no place in the inlet's disc (centre " + number_text(centre.x) + ", " +
        number_text(centre.y) + ", " + number_text(centre.z) + ", radius " + number_text(radius) +
        " m) is " + (pl.has_inlet ? "clear of the wall" : "inside the wall and clear of it") +
        " for a particle of radius " + number_text(r) + " m; " +
        (pl.has_inlet ? "move placement.inlet or change its inlet_radius"
                      : "give placement.inlet and inlet_radius"));
  // Time for a layer to move D = s along dir with speed v0 and acceleration a = g . dir.
  const double D = s, a = dot(gravity, dir);
  double tau = D / v0;
  if (std::fabs(a) > 1e-12) {
    const double disc2 = v0 * v0 + 2 * a * D;
    if (disc2 < 0)
      return invalid_argument("placement.velocity: " + number_text(v0) +
                              " m/s is too slow against gravity to leave the inlet");
    // (sqrt(disc2) - v0) / a, written without the difference that loses
    // every digit when 2 a D is tiny against v0^2 (a fast jet in weak gravity:
    // tau came out 0, and the rate check passed whatever the rate).
    tau = 2 * D / (v0 + std::sqrt(disc2));
  }
  const double capacity = double(disc.size()) / tau;
  if (pl.rate > capacity * (1 + 1e-9)) {
    // Slots grow with the inlet's area: the radius that would carry the rate.
    const double wider = r + (radius - r) * std::sqrt(pl.rate / capacity) * 1.05;
    return invalid_argument("placement.rate: " + number_text(pl.rate) +
                            " particles/s is more than the inlet delivers at " +
                            number_text(v0) + " m/s (" + number_text(std::floor(capacity)) +
                            " particles/s through " + std::to_string(disc.size()) +
                            " slots); widen inlet_radius to about " + number_text(wider) +
                            " m or give a faster velocity");
  }
  if (pl.rate > 0) tau = double(disc.size()) / pl.rate;
  out->v = v;
  out->u = u, out->w = w;
  out->centre = centre;
  out->tau = tau;
  return Status::ok();
}

// Each slot starts at its own random phase within tau: the particles leave as a
// stream, not as flat layers one after another (which the videos showed as falling slabs).
Status inlet(const TriangleMesh& wall, const ParticleSpec& ps, const PlacementSpec& pl,
             Vec3d gravity, SplitMix64& rng, ParticleSet* out) {
  InletLayout lay;
  if (Status st = inlet_layout(wall, ps, pl, gravity, &lay); !st) return st;
  const double r = ps.r_max;
  const std::vector<Vec3d>& disc = lay.disc;
  const Vec3d v = lay.v;
  out->resize(ps.count);
  // Phases spread evenly over [0, 1) and dealt to the slots at random: the
  // stream leaves one particle at a time at the steady rate from the start
  // (independent phases would let the count wander by sqrt(slots)). Within a
  // layer the particles take the slots in the order of their phases, so a last
  // layer that fills only some slots leaves at the rate too (taken in slot
  // order, 500 particles over 1,500 slots left at a third of it).
  std::vector<size_t> by_phase(disc.size());  // the slot of the k-th phase
  const double shift = rng.uniform(0.0, 1.0);
  for (size_t k = 0; k < by_phase.size(); ++k) by_phase[k] = k;
  for (size_t k = by_phase.size(); k > 1; --k)
    std::swap(by_phase[k - 1], by_phase[std::min(k - 1, size_t(rng.uniform() * double(k)))]);
  const double jitter = 0.02 * r;
  const double speed = length(v);
  for (uint64_t i = 0; i < ps.count; ++i) {
    const size_t k = i % disc.size(), slot = by_phase[k];
    const Vec3d p = lay.centre + disc[slot];
    out->x[i] = p.x + rng.uniform(-jitter, jitter);
    out->y[i] = p.y + rng.uniform(-jitter, jitter);
    out->z[i] = p.z + rng.uniform(-jitter, jitter);
    // Each leaves within a cone of kInletSpread about the inlet's direction, at its
    // speed: a collimated stream stacks its particles into columns on a flat floor,
    // which stand up to the inlet, where releases then wait for their place.
    const double reach = kInletSpread * std::sqrt(rng.uniform()), turn = 2 * M_PI * rng.uniform();
    const Vec3d d = v * (1.0 / speed) + lay.u * (reach * std::cos(turn)) +
                    lay.w * (reach * std::sin(turn));
    const Vec3d vi = d * (speed / length(d));
    out->vx[i] = vi.x, out->vy[i] = vi.y, out->vz[i] = vi.z;
    out->release[i] = (double(i / disc.size()) + (double(k) + shift) / double(disc.size())) * lay.tau;
  }
  return Status::ok();
}

}  // namespace

Expected<ParticleSet> place_particles(const TriangleMesh& wall, const ParticleSpec& ps,
                                      const PlacementSpec& pl, Vec3d gravity, uint64_t seed,
                                      ThreadPool* pool) {
  if (ps.count < 1 || ps.count > (uint64_t(1) << 28))
    return invalid_argument("particles.count must lie in [1, 2^28], got " +
                            std::to_string(ps.count));
  if (!(ps.r_min > 0) || !std::isfinite(ps.r_max) || ps.r_max < ps.r_min)
    return invalid_argument(
        "particles.radius must be positive (a range as [min, max] with min <= max)");
  if (wall.triangles.empty()) return invalid_argument("wall: the wall has no triangles");
  if (!finite3(pl.velocity) || !finite3(pl.inlet) || !finite3(pl.region_lo) ||
      !finite3(pl.region_hi) || !std::isfinite(pl.rate) || pl.rate < 0 ||
      !std::isfinite(pl.inlet_radius) || pl.inlet_radius < 0)
    return invalid_argument("placement: values must be finite (and rate, inlet_radius >= 0)");
  SplitMix64 rng(seed);
  ParticleSet out;
  const Vec3d down = length(gravity) > 0 ? gravity : Vec3d{0, 0, -1};
  Status s = pl.kind == PlacementKind::kFill ? fill(wall, ps, pl, down, rng, &out, pool)
                                             : inlet(wall, ps, pl, gravity, rng, &out);
  if (!s) return s;
  // Sizes last, so a range never changes where particles sit (the lattice fits r_max).
  for (size_t i = 0; i < out.size(); ++i)
    out.r[i] = ps.r_min == ps.r_max ? ps.r_max : rng.uniform(ps.r_min, ps.r_max);
  return out;
}

namespace {

// ReleasePlan::first_contact for an inlet laid out as lay: rays along gravity
// from up to 16 of its slots (fewer on a large wall, so that an assessment stays
// within about 4e6 triangle tests), the nearest hit less the radius, fallen
// with the slots' speed along gravity.
double first_contact_time(const TriangleMesh& wall, const InletLayout& lay, double r,
                          Vec3d gravity) {
  const double g = length(gravity);
  if (!(g > 0) || lay.disc.empty() || wall.triangles.empty()) return -1;
  const Vec3d down = gravity * (1.0 / g);
  const double v0 = dot(lay.v, down);
  // Straight down only: a velocity across gravity bends the path.
  if (length(lay.v - down * v0) > 1e-9 * std::max(1.0, length(lay.v)) || v0 < 0) return -1;
  const size_t triangles = wall.triangles.size();
  const size_t rays = std::clamp<size_t>(size_t(4e6 / double(triangles)), 1, 16);
  const size_t step = (lay.disc.size() + rays - 1) / rays;  // at most `rays` of them
  double nearest = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < lay.disc.size(); k += step)
    for (size_t t = 0; t < triangles; ++t)
      if (const double s = ray_distance(wall, t, lay.centre + lay.disc[k], down); s >= 0)
        nearest = std::min(nearest, s);
  if (!std::isfinite(nearest)) return -1;
  const double fall = std::max(0.0, nearest - r);
  // fall = v0 t + g t^2 / 2, without the difference that loses digits when v0 is large.
  return 2 * fall / (v0 + std::sqrt(v0 * v0 + 2 * g * fall));
}

}  // namespace

Expected<ReleasePlan> plan_release(const TriangleMesh& wall, const ParticleSpec& ps,
                                   const PlacementSpec& pl, Vec3d gravity) {
  ReleasePlan plan;
  if (pl.kind == PlacementKind::kFill) {
    plan.speed = length(pl.velocity);
    return plan;
  }
  InletLayout lay;
  if (Status st = inlet_layout(wall, ps, pl, gravity, &lay); !st) return st;
  plan.slots = lay.disc.size();
  plan.period = lay.tau;
  plan.speed = length(lay.v);
  plan.first_contact = first_contact_time(wall, lay, ps.r_max, gravity);
  // Particle i leaves at (i + shift) tau / slots, shift uniform in [0, 1).
  plan.last_release = double(ps.count) * lay.tau / double(plan.slots);
  return plan;
}

double ReleasePlan::mean_active(double duration) const {
  if (!(last_release > 0) || !(duration > 0)) return 1.0;
  // Released at a steady rate from 0 to last_release: the share out at time t is
  // min(1, t / last_release); its mean over [0, duration]:
  if (last_release <= duration) return 1.0 - last_release / (2.0 * duration);
  return duration / (2.0 * last_release);
}

}  // namespace collido::sim
