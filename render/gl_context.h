// An offscreen OpenGL 3.3 core context, behind an interface so that a second
// implementation (EGL with a surfaceless display) can replace OSMesa, which Mesa
// removed in 25.1. The renderer draws into its own framebuffer object, so a
// context needs no window-system surface of the frame's size.
#pragma once

#include <memory>
#include <string>

namespace collido::render {

class GlContext {
 public:
  virtual ~GlContext() = default;
  // Binds the context to the calling thread; false when the driver refuses.
  virtual bool make_current() = 0;
  // Address of a GL entry point (core or extension), nullptr when unknown.
  virtual void* get_proc_address(const char* name) = 0;
  // Short name of the implementation, e.g. "osmesa".
  virtual std::string backend() const = 0;
};

// Creates an OSMesa core-profile 3.3 context (llvmpipe), whose rasterizer
// threads follow LP_NUM_THREADS as the program set it at start-up (see
// render/render.h). On failure returns nullptr and puts the reason in *error.
std::unique_ptr<GlContext> create_osmesa_context(std::string* error);

// The default offscreen context of this build (OSMesa today).
std::unique_ptr<GlContext> create_offscreen_context(std::string* error);

}  // namespace collido::render
