// OSMesa implementation of GlContext. Mesa 22 (Debian 12) gives a core profile
// only through OSMesaCreateContextAttribs; the plain OSMesaCreateContext is a
// compatibility context limited to GL 2.1/3.0 with llvmpipe.
#include <GL/osmesa.h>

#include <cstdlib>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "render/gl_context.h"

namespace collido::render {
namespace {

class OsMesaContext final : public GlContext {
 public:
  explicit OsMesaContext(OSMesaContext ctx) : ctx_(ctx), dummy_(4 * kSide * kSide) {}
  ~OsMesaContext() override {
    if (ctx_) OSMesaDestroyContext(ctx_);
  }
  bool make_current() override {
    // OSMesa needs a colour buffer to make a context current; frames go to an
    // FBO, so a tiny buffer is enough.
    return OSMesaMakeCurrent(ctx_, dummy_.data(), GL_UNSIGNED_BYTE, kSide, kSide) == GL_TRUE;
  }
  void* get_proc_address(const char* name) override {
    return reinterpret_cast<void*>(OSMesaGetProcAddress(name));
  }
  std::string backend() const override { return "osmesa"; }

 private:
  static constexpr int kSide = 16;
  OSMesaContext ctx_;
  std::vector<unsigned char> dummy_;
};

}  // namespace

std::unique_ptr<GlContext> create_osmesa_context(std::string* error) {
    const int attribs[] = {OSMESA_FORMAT,
                         OSMESA_RGBA,
                         OSMESA_DEPTH_BITS,
                         0,  // depth lives in the renderer's FBO
                         OSMESA_STENCIL_BITS,
                         0,
                         OSMESA_ACCUM_BITS,
                         0,
                         OSMESA_PROFILE,
                         OSMESA_CORE_PROFILE,
                         OSMESA_CONTEXT_MAJOR_VERSION,
                         3,
                         OSMESA_CONTEXT_MINOR_VERSION,
                         3,
                         0};
  OSMesaContext ctx = OSMesaCreateContextAttribs(attribs, nullptr);
  if (!ctx) {
    if (error) *error = "OSMesa could not create an OpenGL 3.3 core-profile context";
    return nullptr;
  }
  auto out = std::make_unique<OsMesaContext>(ctx);
  if (!out->make_current()) {
    if (error) *error = "OSMesaMakeCurrent failed";
    return nullptr;
  }
  return out;
}

std::unique_ptr<GlContext> create_offscreen_context(std::string* error) {
  return create_osmesa_context(error);
}

}  // namespace collido::render
