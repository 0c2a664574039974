#include "render/gl_functions.h"

namespace collido::render {

std::string GlFunctions::load(GlContext& context) {
#define COLLIDO_GL_LOAD(type, name)                                    \
  name = reinterpret_cast<type>(context.get_proc_address("gl" #name)); \
  if (!name) return "gl" #name;
  COLLIDO_GL_FUNCTIONS(COLLIDO_GL_LOAD)
#undef COLLIDO_GL_LOAD
  return {};
}

}  // namespace collido::render
