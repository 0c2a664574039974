#include "render/colormap.h"

#include <algorithm>
#include <cmath>

namespace collido::render {
namespace {

// Viridis (van der Walt & Smith, matplotlib; released under CC0), every 8th entry
// of its 256-entry table plus the last. Linear interpolation between these
// differs from the full table by less than one 8-bit step.
struct Knot {
  int index;
  float r, g, b;
};
constexpr Knot kKnots[] = {
    {0, 0.267004f, 0.004874f, 0.329415f},   {8, 0.277018f, 0.050344f, 0.375715f},
    {16, 0.282327f, 0.094955f, 0.417331f},  {24, 0.282884f, 0.135920f, 0.453427f},
    {32, 0.278826f, 0.175490f, 0.483397f},  {40, 0.270595f, 0.214069f, 0.507052f},
    {48, 0.258965f, 0.251537f, 0.524736f},  {56, 0.244972f, 0.287675f, 0.537260f},
    {64, 0.229739f, 0.322361f, 0.545706f},  {72, 0.214298f, 0.355619f, 0.551184f},
    {80, 0.199430f, 0.387607f, 0.554642f},  {88, 0.185556f, 0.418570f, 0.556753f},
    {96, 0.172719f, 0.448791f, 0.557885f},  {104, 0.160665f, 0.478540f, 0.558115f},
    {112, 0.149039f, 0.508051f, 0.557250f}, {120, 0.137770f, 0.537492f, 0.554906f},
    {128, 0.127568f, 0.566949f, 0.550556f}, {136, 0.120565f, 0.596422f, 0.543611f},
    {144, 0.120638f, 0.625828f, 0.533488f}, {152, 0.132268f, 0.655014f, 0.519661f},
    {160, 0.157851f, 0.683765f, 0.501686f}, {168, 0.196571f, 0.711827f, 0.479221f},
    {176, 0.246070f, 0.738910f, 0.452024f}, {184, 0.304148f, 0.764704f, 0.419943f},
    {192, 0.369214f, 0.788888f, 0.382914f}, {200, 0.440137f, 0.811138f, 0.340967f},
    {208, 0.515992f, 0.831158f, 0.294279f}, {216, 0.595839f, 0.848717f, 0.243329f},
    {224, 0.678489f, 0.863742f, 0.189503f}, {232, 0.762373f, 0.876424f, 0.137064f},
    {240, 0.845561f, 0.887322f, 0.099702f}, {248, 0.926106f, 0.897330f, 0.104071f},
    {255, 0.993248f, 0.906157f, 0.143936f},
};

uint8_t to8(float v) {
  return static_cast<uint8_t>(std::lround(std::clamp(v, 0.f, 1.f) * 255.f));
}

}  // namespace

Rgb8 viridis(float t) {
  if (!(t > 0.f)) t = 0.f;  // NaN lands on the low end, not on garbage
  if (t > 1.f) t = 1.f;
  const float u = t * 255.f;
  constexpr int n = sizeof(kKnots) / sizeof(kKnots[0]);
  int k = 0;
  while (k + 2 < n && kKnots[k + 1].index <= u) ++k;
  const Knot& a = kKnots[k];
  const Knot& b = kKnots[k + 1];
  const float w = std::clamp((u - a.index) / float(b.index - a.index), 0.f, 1.f);
  return {to8(a.r + w * (b.r - a.r)), to8(a.g + w * (b.g - a.g)), to8(a.b + w * (b.b - a.b))};
}

const std::array<Rgb8, 256>& viridis_table() {
  static const std::array<Rgb8, 256> table = [] {
    std::array<Rgb8, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = viridis(i / 255.f);
    return t;
  }();
  return table;
}

}  // namespace collido::render
