// Scene documents into the parser; a parsed scene must write itself back in
// a form that parses again.
#include <cstdint>
#include <string>

#include "scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto scene = collido::scene::parse_scene(text);
  if (scene && !collido::scene::parse_scene(collido::scene::to_json(*scene))) __builtin_trap();
  return 0;
}
