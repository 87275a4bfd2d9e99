// Splat renderer.
#include "splat_renderer.hpp"

#include <chrono>
#include <cmath>
#include <string>

#include <glm/gtc/type_ptr.hpp>

#include "error.hpp"
#include "shaders.hpp"

namespace softshell::viewer {

SplatRenderer::SplatRenderer() {
  program_ = build_program("splat.vert", std::string(shader_source("splat.vert")), "splat.frag",
                           std::string(shader_source("splat.frag")));
  glGenVertexArrays(1, &vao_);  // core profile needs one bound, even with no attributes
  glGenBuffers(1, &splat_buffer_);
  glGenBuffers(1, &sort_buffer_);
  glGenTextures(1, &splat_texture_);
  glGenTextures(1, &order_texture_);
}

void SplatRenderer::wait_for_sort() {
  if (sorting_.valid()) sorting_.wait();
  sorting_ = {};
  have_sorted_ = false;
}

SplatRenderer::~SplatRenderer() {
  wait_for_sort();
  for (GLuint& b : lists_)
    if (b) glDeleteBuffers(1, &b);
  glDeleteBuffers(1, &splat_buffer_);
  glDeleteBuffers(1, &sort_buffer_);
  glDeleteTextures(1, &splat_texture_);
  glDeleteTextures(1, &order_texture_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteProgram(program_);
}

void SplatRenderer::upload(const SplatSet& set) {
  GLint max_texels = 0;
  glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &max_texels);
  if (set.splats.size() * 7 > std::size_t(max_texels))
    throw InputError(std::to_string(set.splats.size()) + " splats exceed this OpenGL's texture buffer limit of " +
                     std::to_string(max_texels / 7) + "; raise --threshold");
  wait_for_sort();  // the worker reads set_
  set_ = set;
  glBindBuffer(GL_TEXTURE_BUFFER, splat_buffer_);
  glBufferData(GL_TEXTURE_BUFFER, GLsizeiptr(set.splats.size() * sizeof(Splat)), set.splats.data(), GL_STATIC_DRAW);
  glBindTexture(GL_TEXTURE_BUFFER, splat_texture_);
  glTexBuffer(GL_TEXTURE_BUFFER, GL_RGBA32F, splat_buffer_);
  for (GLuint& b : lists_)
    if (b) glDeleteBuffers(1, &b), b = 0;
  list_bytes_ = 0;
  bound_order_ = 0;
}

GLuint SplatRenderer::list_buffer(int list) {
  // Built on first use: the paper precomputes all six display lists; here a
  // list costs one stable sort, and a session often needs only two or three.
  if (!lists_[list]) {
    const std::vector<std::uint32_t> order = axis_order(set_, list / 2, list % 2 == 1);
    glGenBuffers(1, &lists_[list]);
    glBindBuffer(GL_TEXTURE_BUFFER, lists_[list]);
    glBufferData(GL_TEXTURE_BUFFER, GLsizeiptr(order.size() * 4), order.data(), GL_STATIC_DRAW);
    list_bytes_ += order.size() * 4;
  }
  return lists_[list];
}

void SplatRenderer::bind_order(GLuint buffer) {
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_BUFFER, order_texture_);
  if (buffer != bound_order_) {
    glTexBuffer(GL_TEXTURE_BUFFER, GL_R32UI, buffer);
    bound_order_ = buffer;
  }
}

DrawStats SplatRenderer::draw(const OrbitCamera& camera, const RenderSettings& s, int width, int height) {
  DrawStats stats;
  stats.splats = set_.splats.size();
  glClearColor(s.background.r, s.background.g, s.background.b, 0.0f);
  glClear(GL_COLOR_BUFFER_BIT);
  if (set_.splats.empty()) return stats;

  const glm::vec3 eye = camera.eye();
  if (s.order == DrawOrder::Sort) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto send = [&] {
      glBindBuffer(GL_TEXTURE_BUFFER, sort_buffer_);
      glBufferData(GL_TEXTURE_BUFFER, GLsizeiptr(order_.size() * 4), order_.data(), GL_STREAM_DRAW);
      bound_order_ = 0;  // re-specified storage: attach again
    };
    if (!s.async_sort || !have_sorted_) {
      if (sorting_.valid()) sorting_.wait(), sorting_ = {};
      depth_order(set_, {eye.x, eye.y, eye.z}, order_);
      send();
      have_sorted_ = true;
      sorted_eye_ = eye;
    } else {
      // The newest finished order goes up; a new sort starts when the eye
      // has moved since the order drawn. Drawing never waits for a sort.
      if (sorting_.valid() && sorting_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
        order_ = sorting_.get();
        sorted_eye_ = sorting_eye_;
        send();
      }
      if (!sorting_.valid() && eye != sorted_eye_) {
        sorting_eye_ = eye;
        sorting_ = std::async(std::launch::async, [this, e = eye] {
          std::vector<std::uint32_t> order;
          depth_order(set_, {e.x, e.y, e.z}, order);
          return order;
        });
      }
      stats.stale_order = eye != sorted_eye_;
    }
    bind_order(sort_buffer_);
    stats.sort_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  } else {
    const glm::vec3 f = camera.forward();
    stats.list = axis_list_for_view({f.x, f.y, f.z});
    bind_order(list_buffer(stats.list));
  }

  glUseProgram(program_);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_BUFFER, splat_texture_);
  auto loc = [&](const char* name) { return glGetUniformLocation(program_, name); };
  glUniform1i(loc("u_splats"), 0);
  glUniform1i(loc("u_order"), 1);
  const glm::mat4 vp = camera.projection(float(width) / float(height)) * camera.view();
  glUniformMatrix4fv(loc("u_view_proj"), 1, GL_FALSE, glm::value_ptr(vp));
  glUniform3fv(loc("u_eye"), 1, glm::value_ptr(eye));
  glUniform1i(loc("u_isotropic"), s.method == SplatMethod::Isotropic ? 1 : 0);
  const float iso = float(set_.isotropic_size());
  glUniform3fv(loc("u_iso_s"), 1, glm::value_ptr(iso * camera.right()));
  glUniform3fv(loc("u_iso_t"), 1, glm::value_ptr(iso * camera.up()));
  glUniform1i(loc("u_three_normals"), s.three_normals ? 1 : 0);
  const float laz = glm::radians(s.light_azimuth), lel = glm::radians(s.light_elevation);
  const glm::vec3 light =
      glm::normalize(camera.to_world({std::sin(laz) * std::cos(lel), std::sin(lel), std::cos(laz) * std::cos(lel)}));
  glUniform3fv(loc("u_light"), 1, glm::value_ptr(light));
  glUniform3fv(loc("u_colour"), 1, glm::value_ptr(s.colour));
  glUniform3fv(loc("u_colour2"), 1, glm::value_ptr(s.colour2));
  glUniform3f(loc("u_depth"), s.depth_colour ? 1.0f : 0.0f, s.depth_lo, s.depth_hi);
  glUniform4f(loc("u_material"), s.ambient, s.diffuse, s.specular, s.shininess);
  glUniform1f(loc("u_occlusion"), set_.params.occlusion ? s.occlusion : 0.0f);
  // Crop box from volume fractions to mm (half a voxel of slack each way).
  glm::vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    const float o = float(set_.origin[a]), ext = float(set_.spacing[a] * double(set_.dims[a] - 1));
    const float eps = 0.5f * float(set_.spacing[a]);
    lo[a] = s.crop_lo[a] <= 0.0f ? -1e30f : o + s.crop_lo[a] * ext - eps;
    hi[a] = s.crop_hi[a] >= 1.0f ? 1e30f : o + s.crop_hi[a] * ext + eps;
  }
  glUniform3fv(loc("u_crop_lo"), 1, glm::value_ptr(lo));
  glUniform3fv(loc("u_crop_hi"), 1, glm::value_ptr(hi));
  const float clen = glm::length(s.clip_normal);
  const glm::vec3 cn = clen > 0 ? s.clip_normal / clen : glm::vec3(0.0f);
  glUniform4f(loc("u_clip"), cn.x, cn.y, cn.z, clen > 0 ? -glm::dot(cn, s.clip_point) : -1.0f);
  glUniform1f(loc("u_lambda"), float(set_.lambda));

  glDisable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  glEnable(GL_BLEND);
  // Colour: "over" onto the background; alpha: the accumulated opacity.
  glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
  glBindVertexArray(vao_);
  glDrawArrays(GL_TRIANGLES, 0, GLsizei(set_.splats.size() * 3));
  glBindVertexArray(0);
  glUseProgram(0);
  return stats;
}

std::size_t SplatRenderer::memory_bytes() const {
  return set_.splats.size() * sizeof(Splat) + list_bytes_ + order_.capacity() * 4;
}

}  // namespace softshell::viewer
