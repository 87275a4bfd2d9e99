// The GLSL sources of viewer/shaders/, embedded at build time by
// viewer/cmake/embed_shaders_script.cmake (generated viewer_shaders.cpp).
#pragma once

#include <string>
#include <string_view>

namespace softshell::viewer {

// Verbatim source of viewer/shaders/<name>; throws std::logic_error when
// there is no such shader (a bug, not bad input).
std::string_view shader_source(std::string_view name);

}  // namespace softshell::viewer
