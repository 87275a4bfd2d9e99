// GLFW window and context, shader programs, offscreen framebuffer.
#include "gl_context.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <thread>

#include "error.hpp"

namespace softshell::viewer {
namespace {

std::string g_glfw_error;  // last GLFW error, for the messages below

void glfw_error_callback(int code, const char* text) {
  g_glfw_error = std::string(text ? text : "") + " (GLFW error " + std::to_string(code) + ")";
}

int g_contexts = 0;  // glfwTerminate when the last context goes

// glfwInit, with more tries when a display is named: an X server that is
// still coming up (xvfb-run on a loaded machine) refuses connections for a
// moment, and a first refusal then was the whole error. Without a display
// the first failure stands.
bool init_glfw() {
  if (glfwInit()) return true;
  const char* x = std::getenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  if (!(x && *x) && !(wayland && *wayland)) return false;
  for (int attempt = 0; attempt < 10; ++attempt) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    if (glfwInit()) return true;
  }
  return false;
}

}  // namespace

GlContext::GlContext(int width, int height, const std::string& title, bool visible) {
  glfwSetErrorCallback(glfw_error_callback);
  if (g_contexts == 0 && !init_glfw())
    throw InputError("no display: run under xvfb-run -a or set DISPLAY (" + g_glfw_error + ")");
  ++g_contexts;
  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
  window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (!window_) {
    if (--g_contexts == 0) glfwTerminate();
    throw InputError("no OpenGL 3.3 core context: " + g_glfw_error);
  }
  glfwMakeContextCurrent(window_);
  glfwSwapInterval(visible ? 1 : 0);
}

GlContext::~GlContext() {
  glfwDestroyWindow(window_);
  if (--g_contexts == 0) glfwTerminate();
}

std::string GlContext::description() const {
  auto str = [](GLenum e) {
    const GLubyte* s = glGetString(e);
    return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
  };
  return "OpenGL " + str(GL_VERSION) + ", " + str(GL_RENDERER);
}

namespace {

GLuint compile(GLenum stage, const std::string& name, const std::string& src) {
  const GLuint s = glCreateShader(stage);
  const char* text = src.c_str();
  glShaderSource(s, 1, &text, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetShaderiv(s, GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetShaderInfoLog(s, len, nullptr, log.data());
    glDeleteShader(s);
    throw std::runtime_error("shader " + name + " failed to compile:\n" + log);
  }
  return s;
}

}  // namespace

GLuint build_program(const std::string& vertex_name, const std::string& vertex_src,
                     const std::string& fragment_name, const std::string& fragment_src) {
  const GLuint vs = compile(GL_VERTEX_SHADER, vertex_name, vertex_src);
  const GLuint fs = compile(GL_FRAGMENT_SHADER, fragment_name, fragment_src);
  const GLuint p = glCreateProgram();
  glAttachShader(p, vs);
  glAttachShader(p, fs);
  glLinkProgram(p);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    GLint len = 0;
    glGetProgramiv(p, GL_INFO_LOG_LENGTH, &len);
    std::string log(std::size_t(std::max(len, 1)), '\0');
    glGetProgramInfoLog(p, len, nullptr, log.data());
    glDeleteProgram(p);
    throw std::runtime_error("program " + vertex_name + " + " + fragment_name + " failed to link:\n" + log);
  }
  return p;
}

Framebuffer::Framebuffer(int width, int height) : width_(width), height_(height) {
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
  if (width < 1 || height < 1 || width > max_size || height > max_size)
    throw InputError("image size " + std::to_string(width) + "x" + std::to_string(height) +
                     " outside what OpenGL allows here (1 to " + std::to_string(max_size) + ")");
  glGenFramebuffers(1, &fbo_);
  glGenRenderbuffers(1, &colour_);
  glBindRenderbuffer(GL_RENDERBUFFER, colour_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error("offscreen framebuffer incomplete");
}

Framebuffer::~Framebuffer() {
  glDeleteFramebuffers(1, &fbo_);
  glDeleteRenderbuffers(1, &colour_);
}

void Framebuffer::bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, width_, height_);
}

std::vector<std::uint8_t> Framebuffer::read_rgba() const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  return read_pixels_rgba(width_, height_);
}

std::vector<std::uint8_t> read_pixels_rgba(int width, int height) {
  const std::size_t row = std::size_t(width) * 4;
  std::vector<std::uint8_t> px(row * std::size_t(height));
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, px.data());
  // GL's rows run bottom to top.
  std::vector<std::uint8_t> tmp(row);
  for (int y = 0; y < height / 2; ++y) {
    std::uint8_t* a = &px[std::size_t(y) * row];
    std::uint8_t* b = &px[std::size_t(height - 1 - y) * row];
    std::memcpy(tmp.data(), a, row);
    std::memcpy(a, b, row);
    std::memcpy(b, tmp.data(), row);
  }
  return px;
}

}  // namespace softshell::viewer
