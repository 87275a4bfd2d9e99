// Mesh renderer (see mesh_renderer.hpp).
#include "mesh_renderer.hpp"

#include <chrono>
#include <cmath>
#include <stdexcept>

#include <glm/gtc/type_ptr.hpp>

#include "error.hpp"
#include "shaders.hpp"

namespace softshell::viewer {
namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

MeshRenderer::MeshRenderer() {
  program_ = build_program("mesh.vert", std::string(shader_source("mesh.vert")), "mesh.frag",
                           std::string(shader_source("mesh.frag")));
  glGenVertexArrays(1, &vao_);
  glGenBuffers(1, &vbo_);
  glGenBuffers(1, &ebo_);
}

MeshRenderer::~MeshRenderer() {
  glDeleteBuffers(1, &vbo_);
  glDeleteBuffers(1, &ebo_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteProgram(program_);
}

void MeshRenderer::upload(const Mesh& mesh) {
  // Interleaved position + normal, 24 bytes per vertex.
  std::vector<float> interleaved(mesh.vertex_count() * 6);
  for (std::size_t i = 0; i < mesh.vertex_count(); ++i)
    for (int a = 0; a < 3; ++a) {
      interleaved[6 * i + a] = mesh.positions[3 * i + a];
      interleaved[6 * i + 3 + a] = mesh.normals[3 * i + a];
    }
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(interleaved.size() * sizeof(float)), interleaved.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(mesh.triangles.size() * sizeof(std::uint32_t)),
               mesh.triangles.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 24, reinterpret_cast<const void*>(0));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 24, reinterpret_cast<const void*>(12));
  glBindVertexArray(0);
  triangles_ = mesh.triangle_count();
}

void MeshRenderer::draw(const OrbitCamera& camera, const RenderSettings& s, int width, int height, glm::vec3 crop_lo,
                        glm::vec3 crop_hi) {
  glClearColor(s.background.r, s.background.g, s.background.b, 0.0f);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  if (triangles_ == 0) return;
  glUseProgram(program_);
  auto loc = [&](const char* name) { return glGetUniformLocation(program_, name); };
  const glm::mat4 vp = camera.projection(float(width) / float(height)) * camera.view();
  glUniformMatrix4fv(loc("u_view_proj"), 1, GL_FALSE, glm::value_ptr(vp));
  const glm::vec3 eye = camera.eye();
  glUniform3fv(loc("u_eye"), 1, glm::value_ptr(eye));
  const float laz = glm::radians(s.light_azimuth), lel = glm::radians(s.light_elevation);
  const glm::vec3 light =
      glm::normalize(camera.to_world({std::sin(laz) * std::cos(lel), std::sin(lel), std::cos(laz) * std::cos(lel)}));
  glUniform3fv(loc("u_light"), 1, glm::value_ptr(light));
  glUniform3fv(loc("u_colour"), 1, glm::value_ptr(s.colour));
  glUniform3f(loc("u_depth"), s.depth_colour ? 1.0f : 0.0f, s.depth_lo, s.depth_hi);
  glUniform4f(loc("u_material"), s.ambient, s.diffuse, s.specular, s.shininess);
  glUniform3fv(loc("u_crop_lo"), 1, glm::value_ptr(crop_lo));
  glUniform3fv(loc("u_crop_hi"), 1, glm::value_ptr(crop_hi));
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);  // two-sided: crops and open borders show the inside
  glDisable(GL_BLEND);
  glBindVertexArray(vao_);
  glDrawElements(GL_TRIANGLES, GLsizei(triangles_ * 3), GL_UNSIGNED_INT, nullptr);
  glBindVertexArray(0);
  glUseProgram(0);
  glDisable(GL_DEPTH_TEST);
}

MeshHeadless::MeshHeadless(int width, int height)
    : context_(64, 64, "softshell mesh", false), width_(width), height_(height), renderer_() {
  glGenRenderbuffers(1, &colour_);
  glBindRenderbuffer(GL_RENDERBUFFER, colour_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glGenRenderbuffers(1, &depth_);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  glGenFramebuffers(1, &fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error("mesh framebuffer incomplete");
}

MeshHeadless::~MeshHeadless() {
  glfwMakeContextCurrent(context_.window());
  glDeleteFramebuffers(1, &fbo_);
  glDeleteRenderbuffers(1, &colour_);
  glDeleteRenderbuffers(1, &depth_);
}

void MeshHeadless::upload(const Mesh& mesh) {
  glfwMakeContextCurrent(context_.window());
  renderer_.upload(mesh);
}

double MeshHeadless::render(const OrbitCamera& camera, const RenderSettings& settings, glm::vec3 crop_lo,
                            glm::vec3 crop_hi) {
  glfwMakeContextCurrent(context_.window());
  const auto t0 = Clock::now();
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, width_, height_);
  renderer_.draw(camera, settings, width_, height_, crop_lo, crop_hi);
  glFinish();
  return since(t0);
}

RgbaImage MeshHeadless::read() const {
  glfwMakeContextCurrent(context_.window());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  RgbaImage img;
  img.width = width_;
  img.height = height_;
  img.rgba = read_pixels_rgba(width_, height_);
  return img;
}

RgbaImage render_mesh_image(const Mesh& mesh, const OrbitCamera& camera, const RenderSettings& settings, int width,
                            int height, MeshFrameTiming* timing) {
  MeshHeadless r(width, height);
  const auto t0 = Clock::now();
  r.upload(mesh);
  glFinish();
  const double upload = since(t0);
  r.render(camera, settings);  // warm-up (shader compilation in the driver)
  const double draw = r.render(camera, settings);
  if (timing) *timing = {upload, draw};
  return r.read();
}

}  // namespace softshell::viewer
