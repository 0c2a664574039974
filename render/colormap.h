// Perceptual colour map for particle speed (viridis), shared by the GPU lookup
// texture and the CPU-drawn legend so both show exactly the same colours.
#pragma once

#include <array>
#include <cstdint>

namespace collido::render {

struct Rgb8 {
  uint8_t r, g, b;
};

// Viridis at t in [0, 1] (clamped), as 8-bit sRGB.
Rgb8 viridis(float t);

// The 256-entry table the renderer uploads as its colour-map texture.
const std::array<Rgb8, 256>& viridis_table();

// Colours of the contact mode: particles touching the wall, and the others.
inline constexpr Rgb8 kContactColor{242, 110, 34};
inline constexpr Rgb8 kFreeColor{86, 146, 230};

}  // namespace collido::render
