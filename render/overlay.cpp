#include "render/overlay.h"

#include <ft2build.h>
#include FT_FREETYPE_H

#include <algorithm>
#include <cmath>

namespace collido::render {
namespace {

// Minimal UTF-8 decoding; malformed bytes become U+FFFD rather than stopping.
std::vector<uint32_t> decode_utf8(const std::string& s) {
  std::vector<uint32_t> out;
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = s[i];
    int len = c < 0x80 ? 1 : (c >> 5) == 6 ? 2 : (c >> 4) == 14 ? 3 : (c >> 3) == 30 ? 4 : 0;
    if (len == 0 || i + len > s.size()) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    uint32_t cp = len == 1 ? c : c & (0x7F >> len);
    for (int k = 1; k < len; ++k) cp = (cp << 6) | (static_cast<unsigned char>(s[i + k]) & 0x3F);
    out.push_back(cp);
    i += len;
  }
  return out;
}

inline void blend(uint8_t* px, Rgb8 c, float a) {
  px[0] = static_cast<uint8_t>(px[0] + (c.r - px[0]) * a + 0.5f);
  px[1] = static_cast<uint8_t>(px[1] + (c.g - px[1]) * a + 0.5f);
  px[2] = static_cast<uint8_t>(px[2] + (c.b - px[2]) * a + 0.5f);
}

}  // namespace

std::unique_ptr<Font> Font::open(const std::string& path, int pixel_size, std::string* error) {
  std::unique_ptr<Font> font(new Font());
  FT_Library lib = nullptr;
  if (FT_Init_FreeType(&lib) != 0) {
    if (error) *error = "FreeType could not be initialised";
    return nullptr;
  }
  font->library_ = lib;
  FT_Face face = nullptr;
  if (FT_New_Face(lib, path.c_str(), 0, &face) != 0) {
    if (error) *error = "cannot load font " + path + " (install fonts-dejavu-core)";
    return nullptr;
  }
  font->face_ = face;
  if (FT_Set_Pixel_Sizes(face, 0, std::max(4, pixel_size)) != 0) {
    if (error) *error = "font " + path + " has no size " + std::to_string(pixel_size);
    return nullptr;
  }
  font->ascender_ = static_cast<int>(face->size->metrics.ascender >> 6);
  font->line_height_ = static_cast<int>(face->size->metrics.height >> 6);
  return font;
}

Font::~Font() {
  if (face_) FT_Done_Face(static_cast<FT_Face>(face_));
  if (library_) FT_Done_FreeType(static_cast<FT_Library>(library_));
}

const Font::Glyph& Font::glyph(uint32_t cp) {
  auto it = cache_.find(cp);
  if (it != cache_.end()) return it->second;
  Glyph g;
  FT_Face face = static_cast<FT_Face>(face_);
  if (FT_Load_Char(face, cp, FT_LOAD_RENDER | FT_LOAD_TARGET_LIGHT) == 0) {
    const FT_Bitmap& bm = face->glyph->bitmap;
    g.width = static_cast<int>(bm.width);
    g.rows = static_cast<int>(bm.rows);
    g.left = face->glyph->bitmap_left;
    g.top = face->glyph->bitmap_top;
    g.advance = static_cast<int>((face->glyph->advance.x + 32) >> 6);
    g.coverage.resize(size_t(g.width) * g.rows);
    for (int r = 0; r < g.rows; ++r)
      for (int c = 0; c < g.width; ++c) {
        const unsigned char* row = bm.buffer + r * bm.pitch;
        // Anti-aliased fonts give 8-bit grey; a bitmap-only font gives 1 bit.
        g.coverage[size_t(r) * g.width + c] = bm.pixel_mode == FT_PIXEL_MODE_MONO
                                                  ? ((row[c >> 3] >> (7 - (c & 7))) & 1) * 255
                                                  : row[c];
      }
  }
  return cache_.emplace(cp, std::move(g)).first->second;
}

void Font::blit(Image& image, const Glyph& g, int x, int y, Rgb8 color, float alpha) {
  const int x0 = x + g.left, y0 = y - g.top;
  for (int r = 0; r < g.rows; ++r) {
    const int py = y0 + r;
    if (py < 0 || py >= image.height) continue;
    for (int c = 0; c < g.width; ++c) {
      const int px = x0 + c;
      if (px < 0 || px >= image.width) continue;
      const uint8_t cov = g.coverage[size_t(r) * g.width + c];
      if (cov) blend(image.pixel(px, py), color, alpha * cov / 255.f);
    }
  }
}

int Font::draw(Image& image, int x, int y, const std::string& text, Rgb8 color, float alpha,
               bool shadow) {
  const auto cps = decode_utf8(text);
  FT_Face face = static_cast<FT_Face>(face_);
  const bool kern = FT_HAS_KERNING(face);
  // Shadow first, one pixel down-right (more at large sizes), under the text.
  for (int pass = shadow ? 0 : 1; pass < 2; ++pass) {
    const int off = pass == 0 ? std::max(1, line_height_ / 18) : 0;
    int pen = x;
    FT_UInt prev = 0;
    for (uint32_t cp : cps) {
      const FT_UInt index = FT_Get_Char_Index(face, cp);
      if (kern && prev && index) {
        FT_Vector delta;
        FT_Get_Kerning(face, prev, index, FT_KERNING_DEFAULT, &delta);
        pen += static_cast<int>(delta.x >> 6);
      }
      const Glyph& g = glyph(cp);
      if (pass == 0)
        blit(image, g, pen + off, y + off, Rgb8{0, 0, 0}, 0.7f * alpha);
      else
        blit(image, g, pen, y, color, alpha);
      pen += g.advance;
      prev = index;
    }
    if (pass == 1) return pen - x;
  }
  return 0;
}

int Font::measure(const std::string& text) {
  FT_Face face = static_cast<FT_Face>(face_);
  int pen = 0;
  FT_UInt prev = 0;
  for (uint32_t cp : decode_utf8(text)) {
    const FT_UInt index = FT_Get_Char_Index(face, cp);
    if (FT_HAS_KERNING(face) && prev && index) {
      FT_Vector delta;
      FT_Get_Kerning(face, prev, index, FT_KERNING_DEFAULT, &delta);
      pen += static_cast<int>(delta.x >> 6);
    }
    pen += glyph(cp).advance;
    prev = index;
  }
  return pen;
}

void fill_rect(Image& image, int x0, int y0, int x1, int y1, Rgb8 color, float alpha) {
  x0 = std::max(x0, 0), y0 = std::max(y0, 0);
  x1 = std::min(x1, image.width), y1 = std::min(y1, image.height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) blend(image.pixel(x, y), color, alpha);
}

}  // namespace collido::render
