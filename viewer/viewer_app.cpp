// The interactive viewer.
#include "viewer_app.hpp"

#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <future>
#include <iostream>
#include <optional>
#include <utility>
#include <vector>

#include "camera.hpp"
#include "cli_render_common.hpp"
#include "error.hpp"
#include "gl_context.hpp"
#include "image.hpp"
#include "mesh.hpp"
#include "mesh_renderer.hpp"
#include "raycast.hpp"

namespace softshell::viewer {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// The GL camera as the ray caster's: the same eye (pan included), axes and field of view.
RayCamera ray_camera(const OrbitCamera& c) {
  RayCamera r;
  const glm::vec3 e = c.eye(), f = c.forward(), rt = c.right(), u = c.up();
  for (int a = 0; a < 3; ++a) r.eye[a] = e[a], r.forward[a] = f[a], r.right[a] = rt[a], r.up[a] = u[a];
  r.fov_y = c.fov_y;
  return r;
}

// A full-screen triangle showing the ray-cast image (rows top to bottom).
constexpr const char* kQuadVert = R"(#version 330 core
out vec2 v_uv;
void main() {
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  v_uv = vec2(0.5 * (p.x + 1.0), 1.0 - 0.5 * (p.y + 1.0));
  gl_Position = vec4(p, 0.0, 1.0);
}
)";
constexpr const char* kQuadFrag = R"(#version 330 core
uniform sampler2D u_image;
in vec2 v_uv;
out vec4 frag_colour;
void main() { frag_colour = vec4(texture(u_image, v_uv).rgb, 1.0); }
)";

class ViewerApp {
 public:
  ViewerApp(Runtime& rt, OpacityInput input, const ViewerOptions& o)
      : rt_(rt),
        input_(std::move(input)),
        o_(o),
        settings_(o.settings),
        params_(o.params),
        mode_(o.renderer),
        mesh_level_(o.mesh_level) {}

  int run() {
    init_gl();
    init_cl();
    double loop_s = 0;  // frames after the first (which builds lists and textures)
    int timed = 0;
    for (int frame = 0; !glfwWindowShouldClose(gl_->window()); ++frame) {
      const auto t0 = Clock::now();
      glfwPollEvents();
      update();
      const bool last = o_.frames > 0 && frame + 1 >= o_.frames;
      render(last && !o_.screenshot.empty() ? o_.screenshot : std::string());
      glfwSwapBuffers(gl_->window());
      if (frame > 0 && !(last && !o_.screenshot.empty())) loop_s += since(t0), ++timed;
      if (last) break;
    }
    if (o_.frames > 0 && !o_.quiet && timed > 0)
      std::printf("view: %d frames after the first, %.1f ms per frame (%.1f fps), window %dx%d\n", timed,
                  1000.0 * loop_s / timed, timed / loop_s, o_.width, o_.height);
    glDeleteTextures(1, &ray_texture_);
    glDeleteVertexArrays(1, &quad_vao_);
    glDeleteProgram(quad_program_);
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    return 0;
  }

 private:
  void init_gl() {
    gl_.emplace(o_.width, o_.height, "softshell view", true);
    renderer_.emplace();
    mesh_renderer_.emplace();
    quad_program_ = build_program("raycast quad.vert", kQuadVert, "raycast quad.frag", kQuadFrag);
    glGenVertexArrays(1, &quad_vao_);
    glGenTextures(1, &ray_texture_);
    glBindTexture(GL_TEXTURE_2D, ray_texture_);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glBindTexture(GL_TEXTURE_2D, 0);
    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini next to the user's data
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(gl_->window(), true);
    ImGui_ImplOpenGL3_Init("#version 330 core");
  }

  void init_cl() {
    grid_ = make_grid(input_.u.dims, input_.u.spacing);
    upload_u();
    regenerate();
    reset_view();
  }

  void upload_u() {
    const std::size_t bytes = input_.u.voxels() * sizeof(float);
    u_buffer_ = rt_.buffer(bytes, CL_MEM_READ_ONLY);
    rt_.queue().enqueueWriteBuffer(u_buffer_, CL_TRUE, 0, bytes, input_.u.data.data());
  }

  // Splats on the device from the current u and threshold, then to GL.
  void regenerate() {
    SplatTiming t;
    const SplatSet set = SplatGenerator(rt_, grid_, params_).generate(u_buffer_, input_.u.origin, &t);
    renderer_->upload(set);
    generate_ms_ = 1000.0 * t.total;
    if (!o_.quiet) std::cout << "view: " << set.splats.size() << " splats in " << generate_ms_ << " ms\n";
  }

  void reset_view() {
    camera_ = OrbitCamera{};
    const auto box = renderer_->splats().splat_box();
    camera_.fit(box[0], box[1]);
    camera_.azimuth = o_.azimuth;
    camera_.elevation = o_.elevation;
  }

  // Compute: a finished re-solve replaces u; input events move the camera.
  void update() {
    if (solving_.valid() && solving_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
      auto [u, report] = solving_.get();
      input_.u = std::move(u);
      solve_report_ = report;
      input_.params = solve_params_;
      solve_seconds_ = since(solve_start_);
      upload_u();
      regenerate();
      mesh_dirty_ = caster_dirty_ = true;
      ++u_version_;  // the mesh and the ray caster follow the new u
    }
    ImGuiIO& io = ImGui::GetIO();
    if (!io.WantCaptureMouse) {
      if (io.MouseDown[0]) camera_.rotate(io.MouseDelta.x, io.MouseDelta.y);
      if (io.MouseDown[1]) camera_.move(io.MouseDelta.x, io.MouseDelta.y, io.DisplaySize.y);
      if (io.MouseWheel != 0.0f) camera_.zoom(io.MouseWheel);
    }
    if (!io.WantCaptureKeyboard) {
      GLFWwindow* w = gl_->window();
      if (pressed(GLFW_KEY_ESCAPE)) glfwSetWindowShouldClose(w, GLFW_TRUE);
      if (pressed(GLFW_KEY_R)) reset_view();
      if (pressed(GLFW_KEY_S)) screenshot_request_ = true;
    }
  }

  // Edge-triggered key state.
  bool pressed(int key) {
    const bool down = glfwGetKey(gl_->window(), key) == GLFW_PRESS;
    const bool was = keys_down_[key];
    keys_down_[key] = down;
    return down && !was;
  }

  // Draw: the scene, an optional screenshot of it, then the panel on top.
  void render(const std::string& screenshot_path) {
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(gl_->window(), &fw, &fh);
    if (fw <= 0 || fh <= 0) return;  // minimised
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glViewport(0, 0, fw, fh);
    const auto t0 = Clock::now();
    switch (mode_) {
      case ViewRenderer::Splats: stats_ = renderer_->draw(camera_, settings_, fw, fh); break;
      case ViewRenderer::Mesh: draw_mesh(fw, fh); break;
      case ViewRenderer::Raycast: draw_raycast(fw, fh); break;
    }
    glFinish();  // honest frame times (llvmpipe would otherwise queue)
    const double ms = 1000.0 * since(t0);
    frame_ms_ = frame_ms_ == 0 ? ms : 0.9 * frame_ms_ + 0.1 * ms;

    // The panel goes into a --frames screenshot only with --screenshot-panel
    // (documentation pictures); S saves the scene alone.
    const bool with_panel = o_.screenshot_panel && !screenshot_path.empty();
    if (with_panel) draw_panel();
    std::string path = screenshot_path;
    if (path.empty() && screenshot_request_) {
      char name[64];
      std::snprintf(name, sizeof name, "softshell-view-%03d.png", screenshots_++);
      path = name;
    }
    screenshot_request_ = false;
    if (!path.empty()) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
      glReadBuffer(GL_BACK);
      const std::vector<std::uint8_t> px = read_pixels_rgba(fw, fh);
      Image img(fw, fh);
      for (std::size_t i = 0; i < std::size_t(fw) * fh; ++i)
        for (int c = 0; c < 3; ++c) img.rgb[i * 3 + c] = px[i * 4 + c];
      write_png(path, img);
      status_ = "saved " + path;
      if (!o_.quiet) std::cout << "view: screenshot " << path << " (" << fw << "x" << fh << ")\n";
    }

    if (!with_panel) draw_panel();
  }

  // The crop box (volume fractions) in mm with half a voxel of slack, as the splat renderer's.
  std::pair<glm::vec3, glm::vec3> crop_mm() const {
    const Volume& u = input_.u;
    glm::vec3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      const float o = float(u.origin[a]), ext = float(u.spacing[a] * double(u.dims[a] - 1));
      const float eps = 0.5f * float(u.spacing[a]);
      lo[a] = settings_.crop_lo[a] <= 0.0f ? -1e30f : o + settings_.crop_lo[a] * ext - eps;
      hi[a] = settings_.crop_hi[a] >= 1.0f ? 1e30f : o + settings_.crop_hi[a] * ext + eps;
    }
    return {lo, hi};
  }

  // Marching Cubes of u at the level, on the device, then to GL.
  void extract_mesh() {
    MeshTiming t;
    const Mesh mesh = marching_cubes(rt_, input_.u, mesh_level_, &t);
    mesh_renderer_->upload(mesh);
    mesh_triangles_ = mesh.triangle_count();
    mesh_extracted_level_ = mesh_level_;
    mesh_ms_ = 1000.0 * t.total;
    mesh_dirty_ = false;
    if (!o_.quiet)
      std::cout << "view: mesh at level " << mesh_level_ << ": " << mesh_triangles_ << " triangles in " << mesh_ms_
                << " ms\n";
  }

  void draw_mesh(int fw, int fh) {
    if (mesh_dirty_ && !solving_.valid()) {  // no OpenCL work while a solve runs
      try {
        extract_mesh();
      } catch (const std::exception& e) {
        mesh_dirty_ = false;  // until the level or u changes
        status_ = std::string("mesh: ") + e.what();
      }
    }
    const auto [lo, hi] = crop_mm();
    mesh_renderer_->draw(camera_, settings_, fw, fh, lo, hi);
  }

  RaycastParams ray_params() const {
    RaycastParams p;  // opacity = u, as `render --method raycast` on an opacity volume
    p.tf_cut = ray_cut_;
    cli::apply_render_settings(p, settings_);
    return p;
  }

  static std::vector<float> params_key(const RaycastParams& p) {
    std::vector<float> k{p.tf_cut, p.ambient, p.diffuse, p.specular, p.shininess, p.light_azimuth, p.light_elevation};
    for (int a = 0; a < 3; ++a)
      k.insert(k.end(), {p.crop_lo[a], p.crop_hi[a], p.colour[a], p.background[a]});
    return k;
  }

  // Ray casting: the OpenCL ray caster renders the view into an image of the
  // framebuffer's size, shown as a full-screen texture. It re-casts only when
  // the camera, the size, the settings or u change; the ray caster (which
  // holds the volume and its gradients) is rebuilt only when its parameters
  // change, and not while a panel widget is being dragged.
  void draw_raycast(int fw, int fh) {
    const RaycastParams p = ray_params();
    const std::vector<float> pkey = params_key(p);
    std::vector<float> key = pkey;
    const glm::vec3 t = camera_.target;
    key.insert(key.end(), {t.x, t.y, t.z, camera_.distance, camera_.azimuth, camera_.elevation, camera_.fov_y,
                           camera_.pan.x, camera_.pan.y, float(fw), float(fh), float(u_version_)});
    const bool rebuild = caster_dirty_ || !caster_ || pkey != caster_key_;
    const bool hold = solving_.valid() || (rebuild && caster_ && ImGui::IsAnyItemActive());
    if (key != ray_key_ && !hold) {
      ray_key_ = key;
      try {
        p.validate();
        if (rebuild) {
          caster_.reset();
          caster_.emplace(rt_, input_.u, p);
          caster_key_ = pkey;
          caster_dirty_ = false;
        }
        const auto t0 = Clock::now();
        double kernel_s = 0;
        const Image img = caster_->render(ray_camera(camera_), fw, fh, &kernel_s).rgb(p.background);
        glBindTexture(GL_TEXTURE_2D, ray_texture_);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, fw, fh, 0, GL_RGB, GL_UNSIGNED_BYTE, img.rgb.data());
        glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
        glBindTexture(GL_TEXTURE_2D, 0);
        ray_w_ = fw, ray_h_ = fh;
        ray_ms_ = 1000.0 * since(t0);
        ray_kernel_ms_ = 1000.0 * kernel_s;
        ray_error_.clear();
      } catch (const std::exception& e) {  // a bad crop box, or the device out of memory
        ray_error_ = e.what();
      }
    }
    glClearColor(settings_.background.r, settings_.background.g, settings_.background.b, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT);
    if (ray_w_ == 0) return;
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    glUseProgram(quad_program_);
    glUniform1i(glGetUniformLocation(quad_program_, "u_image"), 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, ray_texture_);
    glBindVertexArray(quad_vao_);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glBindVertexArray(0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glUseProgram(0);
  }

  void draw_panel() {
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    panel();
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  }

  void panel() {
    ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(330, 0), ImGuiCond_FirstUseEver);
    ImGui::Begin("softshell");
    const double fps = frame_ms_ > 0 ? 1000.0 / frame_ms_ : 0.0;
    if (mode_ == ViewRenderer::Splats) {
      ImGui::Text("%zu splats, %.1f ms/frame (%.0f fps)", stats_.splats, frame_ms_, fps);
      ImGui::Text("order: %s%s", stats_.list >= 0 ? "presorted list " : "exact sort",
                  stats_.list >= 0 ? (std::string(1, "xyz"[stats_.list / 2]) + (stats_.list % 2 ? " desc" : " asc")).c_str()
                                   : "");
    } else if (mode_ == ViewRenderer::Mesh) {
      ImGui::Text("%zu triangles, %.1f ms/frame (%.0f fps)", mesh_triangles_, frame_ms_, fps);
      ImGui::Text("mesh: level %.2f, extracted in %.1f ms", mesh_extracted_level_, mesh_ms_);
    } else {
      ImGui::Text("ray cast %dx%d: %.0f ms (kernel %.0f ms)", ray_w_, ray_h_, ray_ms_, ray_kernel_ms_);
      ImGui::TextDisabled("re-cast only when the view or settings change");
      if (!ray_error_.empty()) ImGui::TextColored(ImVec4(1.0f, 0.5f, 0.4f, 1.0f), "%s", ray_error_.c_str());
    }
    ImGui::TextDisabled("drag: rotate, right-drag: pan, wheel: zoom\nS: screenshot, R: reset view, Esc: quit");
    if (!status_.empty()) ImGui::TextDisabled("%s", status_.c_str());

    if (ImGui::CollapsingHeader("Rendering", ImGuiTreeNodeFlags_DefaultOpen)) {
      const char* renderers[] = {"oriented splats", "isotropic splats", "Marching Cubes mesh", "ray casting"};
      int renderer = mode_ == ViewRenderer::Mesh      ? 2
                     : mode_ == ViewRenderer::Raycast ? 3
                     : settings_.method == SplatMethod::Isotropic ? 1
                                                                  : 0;
      if (ImGui::Combo("renderer", &renderer, renderers, 4)) {
        mode_ = renderer == 2 ? ViewRenderer::Mesh : renderer == 3 ? ViewRenderer::Raycast : ViewRenderer::Splats;
        if (renderer < 2) settings_.method = renderer == 1 ? SplatMethod::Isotropic : SplatMethod::Oriented;
        frame_ms_ = 0;
      }
      if (mode_ == ViewRenderer::Mesh) {
        ImGui::SliderFloat("level", &mesh_level_, 0.02f, 0.98f, "%.2f");
        if (ImGui::IsItemDeactivatedAfterEdit()) mesh_dirty_ = true;  // re-extracted on release
        if (mesh_triangles_ == 0 && !mesh_dirty_) ImGui::TextDisabled("no surface at this level");
      } else if (mode_ == ViewRenderer::Raycast) {
        ImGui::SliderFloat("opacity cut", &ray_cut_, 0.0f, 0.9f, "%.2f");
      } else {
        splat_controls();
      }
      ImGui::SliderFloat("light azimuth", &settings_.light_azimuth, -90.0f, 90.0f, "%.0f deg");
      ImGui::SliderFloat("light elevation", &settings_.light_elevation, -90.0f, 90.0f, "%.0f deg");
      ImGui::ColorEdit3("colour", &settings_.colour.x, ImGuiColorEditFlags_NoInputs);
      ImGui::SameLine();
      ImGui::ColorEdit3("background", &settings_.background.x, ImGuiColorEditFlags_NoInputs);
    }

    if (ImGui::CollapsingHeader("Cut away", ImGuiTreeNodeFlags_DefaultOpen)) {
      ImGui::DragFloatRange2("crop x", &settings_.crop_lo.x, &settings_.crop_hi.x, 0.005f, 0.0f, 1.0f, "%.2f");
      ImGui::DragFloatRange2("crop y", &settings_.crop_lo.y, &settings_.crop_hi.y, 0.005f, 0.0f, 1.0f, "%.2f");
      ImGui::DragFloatRange2("crop z", &settings_.crop_lo.z, &settings_.crop_hi.z, 0.005f, 0.0f, 1.0f, "%.2f");
      const char* planes[] = {"off", "view-aligned", "x", "y", "z"};
      ImGui::Combo("clip plane", &clip_mode_, planes, 5);
      ImGui::SliderFloat("clip offset", &clip_offset_, -1.0f, 1.0f, "%.2f");
      ImGui::Checkbox("flip side", &clip_flip_);
      if (mode_ != ViewRenderer::Splats && clip_mode_ != 0) ImGui::TextDisabled("(the clip plane cuts splats only)");
      apply_clip();
      if (ImGui::Button("reset cuts")) {
        settings_.crop_lo = glm::vec3(0.0f), settings_.crop_hi = glm::vec3(1.0f);
        clip_mode_ = 0;
      }
    }

    if (ImGui::CollapsingHeader("Classification", ImGuiTreeNodeFlags_DefaultOpen)) {
      if (!input_.classified) {
        ImGui::TextWrapped("The input is an opacity volume; open the raw ultrasound volume to re-classify.");
      } else {
        if (!edit_.has_value()) edit_ = input_.params;
        VariationalParams& p = *edit_;
        const IntensityMap map = input_.data.intensity_map();
        float iso = float(map.from_unit(p.v_iso));
        const float lo = float(map.from_unit(0.0)), hi = float(map.from_unit(1.0));
        if (ImGui::SliderFloat("v_iso", &iso, lo, hi, "%.1f")) p.v_iso = map.to_unit(iso);
        slider("alpha", p.alpha, 0.0f, 10.0f);
        slider("beta", p.beta, 0.0f, 20.0f);
        slider("gamma", p.gamma, 0.01f, 20.0f);
        slider("omega", p.omega, 0.0f, 1.0f);
        slider("delta", p.delta, 0.001f, 1.0f);
        if (solving_.valid()) {
          ImGui::Text("solving (warm start) ... %.1f s", since(solve_start_));
          ImGui::ProgressBar(-1.0f * float(ImGui::GetTime()), ImVec2(-1, 0), "multigrid PCG");
        } else if (ImGui::Button("re-solve (warm start)")) {
          solve_params_ = p;
          solve_start_ = Clock::now();
          // The worker uses the runtime alone: the main thread does no
          // OpenCL work until the future is ready (regenerate is held back).
          solving_ = std::async(std::launch::async, [this, p] {
            const Volume init = input_.u;
            SolveReport report;
            Volume u = reclassify(rt_, input_, p, &init, &report);
            return std::make_pair(std::move(u), report);
          });
        }
        if (solve_seconds_ > 0)
          ImGui::Text("last solve: %.1f s, %d iterations, residual %.1e%s", solve_seconds_, solve_report_.cycles,
                      solve_report_.residuals.empty() ? 0.0 : solve_report_.residuals.back(),
                      solve_report_.converged ? "" : " (not converged)");
      }
    }
    ImGui::Text("splat generation %.1f ms", generate_ms_);
    ImGui::End();
  }

  // The splat-only controls of the Rendering section.
  void splat_controls() {
    int normals = settings_.three_normals;
    ImGui::RadioButton("one normal", &normals, 0);
    ImGui::SameLine();
    ImGui::RadioButton("three normals", &normals, 1);
    settings_.three_normals = normals != 0;
    int order = settings_.order == DrawOrder::Sort;
    ImGui::RadioButton("six lists", &order, 0);
    ImGui::SameLine();
    ImGui::RadioButton("exact sort", &order, 1);
    settings_.order = order ? DrawOrder::Sort : DrawOrder::Lists;
    ImGui::SliderFloat("threshold", &params_.threshold, 0.02f, 0.9f, "%.2f");
    if (ImGui::IsItemDeactivatedAfterEdit() && !solving_.valid()) regenerate();
    // Splat orientation: the structure tensor of u (default) or grad u (the paper).
    int orient = params_.normals == SplatNormals::Tensor ? 0 : 1;
    const int before = orient;
    ImGui::RadioButton("tensor normals", &orient, 0);
    ImGui::SameLine();
    ImGui::RadioButton("grad u normals", &orient, 1);
    if (orient != before && !solving_.valid()) {
      params_.normals = orient == 0 ? SplatNormals::Tensor : SplatNormals::Gradient;
      regenerate();
    }
  }

  static void slider(const char* name, double& v, float lo, float hi) {
    float f = float(v);
    if (ImGui::SliderFloat(name, &f, lo, hi, "%.3f", ImGuiSliderFlags_Logarithmic)) v = f;
  }

  void apply_clip() {
    settings_.clip_normal = glm::vec3(0.0f);
    if (clip_mode_ == 0) return;
    const SplatSet& s = renderer_->splats();
    const glm::vec3 lo{float(s.box_lo()[0]), float(s.box_lo()[1]), float(s.box_lo()[2])};
    const glm::vec3 hi{float(s.box_hi()[0]), float(s.box_hi()[1]), float(s.box_hi()[2])};
    const glm::vec3 centre = 0.5f * (lo + hi);
    glm::vec3 n = clip_mode_ == 1 ? -camera_.forward() : glm::vec3(0.0f);
    if (clip_mode_ >= 2) n[clip_mode_ - 2] = -1.0f;
    // Offset along the normal, in half the box's extent along it.
    const float half = 0.5f * std::abs(glm::dot(glm::abs(n), hi - lo));
    settings_.clip_point = centre - clip_offset_ * half * n;
    settings_.clip_normal = clip_flip_ ? -n : n;
  }

  Runtime& rt_;
  OpacityInput input_;
  ViewerOptions o_;
  RenderSettings settings_;
  SplatParams params_;
  GridDesc grid_{};
  cl::Buffer u_buffer_;
  std::optional<GlContext> gl_;
  std::optional<SplatRenderer> renderer_;
  ViewRenderer mode_;
  // Marching Cubes mesh (extracted lazily: when shown and the level or u changed).
  std::optional<MeshRenderer> mesh_renderer_;
  float mesh_level_, mesh_extracted_level_ = 0;
  bool mesh_dirty_ = true;
  std::size_t mesh_triangles_ = 0;
  double mesh_ms_ = 0;
  // Ray casting: the caster, its parameters, the key of the image shown, the quad.
  std::optional<RayCaster> caster_;
  bool caster_dirty_ = true;
  int u_version_ = 0;
  float ray_cut_ = 0.2f;  // the splats' epsilon, as `render --method raycast`
  std::vector<float> caster_key_, ray_key_;
  GLuint quad_program_ = 0, quad_vao_ = 0, ray_texture_ = 0;
  int ray_w_ = 0, ray_h_ = 0;
  double ray_ms_ = 0, ray_kernel_ms_ = 0;
  std::string ray_error_;
  OrbitCamera camera_;
  DrawStats stats_;
  double frame_ms_ = 0, generate_ms_ = 0, solve_seconds_ = 0;
  bool screenshot_request_ = false;
  int screenshots_ = 0;
  bool keys_down_[GLFW_KEY_LAST + 1] = {};
  std::string status_;
  int clip_mode_ = 0;
  float clip_offset_ = 0.0f;
  bool clip_flip_ = false;
  std::optional<VariationalParams> edit_;
  VariationalParams solve_params_;
  SolveReport solve_report_;
  Clock::time_point solve_start_;
  std::future<std::pair<Volume, SolveReport>> solving_;
};

}  // namespace

int run_viewer(Runtime& rt, OpacityInput input, const ViewerOptions& options) {
  ViewerApp app(rt, std::move(input), options);
  return app.run();
}

}  // namespace softshell::viewer
