// Text and legend drawn on the finished frame on the CPU: glyphs from a real
// font file through FreeType, blended into the image. Drawing after readback
// keeps text crisp and identical across GL backends. Internal to render/.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "render/colormap.h"
#include "render/image.h"

namespace collido::render {

class Font {
 public:
  // Loads the font file at a pixel height (the em size). nullptr and *error
  // when FreeType cannot open it.
  static std::unique_ptr<Font> open(const std::string& path, int pixel_size, std::string* error);
  ~Font();

  // Draws UTF-8 text with its baseline at y and pen start at x (pixels), with a
  // soft dark shadow so it reads on any background; returns the advance.
  int draw(Image& image, int x, int y, const std::string& text, Rgb8 color, float alpha = 1.f,
           bool shadow = true);
  // Width in pixels the text would take.
  int measure(const std::string& text);
  int ascender() const { return ascender_; }
  int line_height() const { return line_height_; }

 private:
  struct Glyph {
    int width = 0, rows = 0, left = 0, top = 0, advance = 0;
    std::vector<uint8_t> coverage;
  };
  Font() = default;
  const Glyph& glyph(uint32_t codepoint);
  void blit(Image& image, const Glyph& g, int x, int y, Rgb8 color, float alpha);

  void* library_ = nullptr;  // FT_Library, kept opaque so FreeType stays out of headers
  void* face_ = nullptr;     // FT_Face
  int ascender_ = 0, line_height_ = 0;
  std::unordered_map<uint32_t, Glyph> cache_;
};

// Blends a filled rectangle [x0, x1) x [y0, y1) over the image.
void fill_rect(Image& image, int x0, int y0, int x1, int y1, Rgb8 color, float alpha);

}  // namespace collido::render
