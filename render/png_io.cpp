// PNG through libpng's simplified API (png_image), which handles every colour
// type and bit depth on reading and needs no setjmp error handling.
#include <png.h>
#include <unistd.h>

#include <cstdio>
#include <string>

#include "common/atomic_file.h"
#include "render/image.h"

namespace collido::render {

Status write_png(const std::string& path, const Image& image, int compression) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != size_t(image.width) * image.height * 3)
    return io_error("write_png " + path + ": image has no pixels or the wrong size");
  const std::string tmp = temp_path_for(path);
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return io_error("write_png: cannot create " + tmp);

  // The simplified writer has no compression setting, so use the classic API;
  // errors longjmp back here.
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    std::remove(tmp.c_str());
    return io_error("write_png " + path + ": out of memory");
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    std::remove(tmp.c_str());
    return io_error("write_png " + path + ": libpng failed (disk full?)");
  }
  png_init_io(png, f);
  png_set_compression_level(png, compression < 0 ? 3 : (compression > 9 ? 9 : compression));
  // Sub filtering only: rendered frames compress nearly as well and it is several
  // times faster than libpng's adaptive choice.
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
  png_set_IHDR(png, info, image.width, image.height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y)
    png_write_row(png, const_cast<png_bytep>(image.pixel(0, y)));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  const bool flushed = std::fflush(f) == 0;
  const bool closed = std::fclose(f) == 0;
  if (!flushed || !closed) {
    std::remove(tmp.c_str());
    return io_error("write_png " + path + ": write failed (disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return io_error("write_png: cannot rename " + tmp + " to " + path);
  }
  return Status::ok();
}

Status read_png(const std::string& path, Image* image) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&img, path.c_str()))
    return io_error("read_png " + path + ": " + img.message);
  img.format = PNG_FORMAT_RGB;
  Image out;
  out.resize(int(img.width), int(img.height));
  if (!png_image_finish_read(&img, nullptr, out.rgb.data(), 0, nullptr)) {
    std::string msg = img.message;
    png_image_free(&img);
    return io_error("read_png " + path + ": " + msg);
  }
  *image = std::move(out);
  return Status::ok();
}

}  // namespace collido::render
