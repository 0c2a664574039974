// 8-bit RGB images in memory and as PNG files (libpng).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/status.h"

namespace collido::render {

// Top row first, 3 bytes (R, G, B) per pixel, no row padding.
struct Image {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;

  void resize(int w, int h) {
    width = w;
    height = h;
    rgb.assign(size_t(w) * size_t(h) * 3, 0);
  }
  const uint8_t* pixel(int x, int y) const { return &rgb[(size_t(y) * width + x) * 3]; }
  uint8_t* pixel(int x, int y) { return &rgb[(size_t(y) * width + x) * 3]; }
};

// Writes an 8-bit RGB PNG through a temporary file renamed into place, so a
// reader never sees half an image. compression: zlib level 0..9 (3 is fast and
// about as small as 9 for rendered frames).
Status write_png(const std::string& path, const Image& image, int compression = 3);

// Reads a PNG (any bit depth or colour type libpng can expand) as 8-bit RGB.
Status read_png(const std::string& path, Image* image);

}  // namespace collido::render
