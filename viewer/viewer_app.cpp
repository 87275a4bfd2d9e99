// The interactive viewer.
#include "viewer_app.hpp"

#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <iostream>
#include <optional>
#include <utility>

#include "camera.hpp"
#include "error.hpp"
#include "gl_context.hpp"
#include "image.hpp"

namespace softshell::viewer {
namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

class ViewerApp {
 public:
  ViewerApp(Runtime& rt, OpacityInput input, const ViewerOptions& o)
      : rt_(rt), input_(std::move(input)), o_(o), settings_(o.settings), params_(o.params) {}

  int run() {
    init_gl();
    init_cl();
    for (int frame = 0; !glfwWindowShouldClose(gl_->window()); ++frame) {
      glfwPollEvents();
      update();
      const bool last = o_.frames > 0 && frame + 1 >= o_.frames;
      render(last && !o_.screenshot.empty() ? o_.screenshot : std::string());
      glfwSwapBuffers(gl_->window());
      if (last) break;
    }
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    return 0;
  }

 private:
  void init_gl() {
    gl_.emplace(o_.width, o_.height, "softshell view", true);
    renderer_.emplace();
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
    stats_ = renderer_->draw(camera_, settings_, fw, fh);
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
    ImGui::Text("%zu splats, %.1f ms/frame (%.0f fps)", stats_.splats, frame_ms_, frame_ms_ > 0 ? 1000.0 / frame_ms_ : 0.0);
    ImGui::Text("order: %s%s", stats_.list >= 0 ? "presorted list " : "exact sort",
                stats_.list >= 0 ? (std::string(1, "xyz"[stats_.list / 2]) + (stats_.list % 2 ? " desc" : " asc")).c_str()
                                 : "");
    ImGui::TextDisabled("drag: rotate, right-drag: pan, wheel: zoom\nS: screenshot, R: reset view, Esc: quit");
    if (!status_.empty()) ImGui::TextDisabled("%s", status_.c_str());

    if (ImGui::CollapsingHeader("Rendering", ImGuiTreeNodeFlags_DefaultOpen)) {
      int method = settings_.method == SplatMethod::Isotropic;
      ImGui::RadioButton("oriented", &method, 0);
      ImGui::SameLine();
      ImGui::RadioButton("isotropic", &method, 1);
      settings_.method = method ? SplatMethod::Isotropic : SplatMethod::Oriented;
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
