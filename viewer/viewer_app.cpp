// The interactive viewer.
#include "viewer_app.hpp"

#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <algorithm>
#include <array>
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
#include "io.hpp"
#include "params_file.hpp"
#include "presets.hpp"
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

// Lines in the 3-D view (the slice planes' outlines), world coordinates in mm.
constexpr const char* kLineVert = R"(#version 330 core
uniform mat4 u_mvp;
layout(location = 0) in vec3 a_pos;
void main() { gl_Position = u_mvp * vec4(a_pos, 1.0); }
)";
constexpr const char* kLineFrag = R"(#version 330 core
uniform vec3 u_colour;
out vec4 frag_colour;
void main() { frag_colour = vec4(u_colour, 1.0); }
)";

// A rectangle in window pixels, origin top left.
struct Rect {
  float x = 0, y = 0, w = 0, h = 0;
};

// The window: the panel docked on the left, the 3-D view beside it, the
// three slice panes in a strip under the 3-D view.
struct Layout {
  Rect panel, view, strip;
  std::array<Rect, 3> pane;
};

Layout window_layout(float w, float h) {
  Layout l;
  const float pw = std::min(340.0f, std::floor(0.4f * w));
  const float rw = w - pw;
  const float sh = std::floor(std::min(rw / 3.0f, 0.38f * h));
  l.panel = {0, 0, pw, h};
  l.view = {pw, 0, rw, h - sh};
  l.strip = {pw, h - sh, rw, sh};
  for (int i = 0; i < 3; ++i)
    l.pane[i] = {pw + std::floor(float(i) * rw / 3.0f), h - sh, std::floor(rw / 3.0f), sh};
  return l;
}

// Slice k shows axes kAxes[k][0] (right) and kAxes[k][1] (down) at a fixed
// index along kAxes[k][2]: axial (x, y at z), coronal (x, z at y), sagittal
// (y, z at x), as `softshell slices` draws them. Each is drawn in the colour
// of its normal axis (x red, y green, z blue), in the panes and in 3-D.
constexpr int kAxes[3][3] = {{0, 1, 2}, {0, 2, 1}, {1, 2, 0}};
constexpr const char* kSliceNames[3] = {"axial", "coronal", "sagittal"};
const ImU32 kAxisColour[3] = {IM_COL32(235, 80, 70, 255), IM_COL32(90, 200, 90, 255), IM_COL32(90, 140, 255, 255)};
const glm::vec3 kAxisColourGl[3] = {{0.92f, 0.31f, 0.27f}, {0.35f, 0.78f, 0.35f}, {0.35f, 0.55f, 1.0f}};
const ImU32 kIsoColour = IM_COL32(255, 40, 40, 255);
constexpr float kPanelGrey = 0.075f;  // behind the docked panel and the slice strip

class ViewerApp {
 public:
  ViewerApp(Runtime& rt, OpacityInput input, const ViewerOptions& o)
      : rt_(rt),
        input_(std::move(input)),
        o_(o),
        settings_(o.settings),
        params_(o.params),
        mode_(o.renderer),
        mesh_level_(o.mesh_level),
        overlay_(o.overlay) {
    if (o.light) settings_.light_azimuth = float((*o.light)[0]), settings_.light_elevation = float((*o.light)[1]);
    if (o.colour) settings_.colour = {float((*o.colour)[0]), float((*o.colour)[1]), float((*o.colour)[2])};
    if (o.background)
      settings_.background = {float((*o.background)[0]), float((*o.background)[1]), float((*o.background)[2])};
    std::snprintf(save_prefix_, sizeof save_prefix_, "%s", "softshell-view");
    preset_ = o.preset;
    settings_.async_sort = true;  // the exact order is sorted off the render thread
    if (o.play_fps > 0) playing_ = true, play_fps_ = float(o.play_fps);
  }

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
    // The last re-solve and its polish (update_solve starts it) before u is saved.
    while (solving_.valid()) solving_.wait(), update_solve();
    if (!o_.save_u.empty()) save_u(o_.save_u);
    if (!o_.save_mesh.empty()) save_mesh(o_.save_mesh);
    if (!o_.save_params.empty()) save_params(o_.save_params);
    if (o_.frames > 0 && !o_.quiet && timed > 0)
      std::printf("view: %d frames after the first, %.1f ms per frame (%.1f fps), window %dx%d\n", timed,
                  1000.0 * loop_s / timed, timed / loop_s, o_.width, o_.height);
    glDeleteTextures(1, &ray_texture_);
    glDeleteVertexArrays(1, &quad_vao_);
    glDeleteProgram(quad_program_);
    glDeleteProgram(line_program_);
    glDeleteBuffers(1, &line_vbo_);
    glDeleteVertexArrays(1, &line_vao_);
    glDeleteTextures(3, slice_textures_);
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
    line_program_ = build_program("line.vert", kLineVert, "line.frag", kLineFrag);
    glGenVertexArrays(1, &line_vao_);
    glGenBuffers(1, &line_vbo_);
    glBindVertexArray(line_vao_);
    glBindBuffer(GL_ARRAY_BUFFER, line_vbo_);
    glBufferData(GL_ARRAY_BUFFER, 24 * 3 * sizeof(float), nullptr, GL_DYNAMIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
    glBindVertexArray(0);
    glBindBuffer(GL_ARRAY_BUFFER, 0);
    glGenTextures(3, slice_textures_);
    for (GLuint t : slice_textures_) {
      glBindTexture(GL_TEXTURE_2D, t);  // nearest: one texel per voxel, grey levels exact
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    }
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
    for (int a = 0; a < 3; ++a)
      cursor_[a] = o_.cursor[a] >= 0 ? std::min(o_.cursor[a], int(input_.u.dims[a]) - 1) : int(input_.u.dims[a]) / 2;
    initial_v_iso_ = input_.params.v_iso;
    settings_.depth_lo = float(input_.u.origin[2]);
    settings_.depth_hi = float(input_.u.origin[2] + input_.u.spacing[2] * double(input_.u.dims[2] - 1));
    build_histogram();
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
    const cl::Buffer* field = nullptr;
    if (params_.normals == SplatNormals::Data) {
      if (field_stale_) field_buffer_ = upload_orientation_field(rt_, input_.bmode, input_.u.dims), field_stale_ = false;
      field = &field_buffer_;
    }
    const SplatSet set = SplatGenerator(rt_, grid_, params_).generate(u_buffer_, input_.u.origin, &t, field);
    renderer_->upload(set);
    // The depth colour map spans what is drawn (near its top light, at its bottom dark).
    if (!set.splats.empty()) {
      const auto box = set.splat_box();
      if (box[1][2] > box[0][2]) settings_.depth_lo = float(box[0][2]), settings_.depth_hi = float(box[1][2]);
    }
    generate_ms_ = 1000.0 * t.total;
    if (!o_.quiet) std::cout << "view: " << set.splats.size() << " splats in " << generate_ms_ << " ms\n";
  }

  void reset_view() {
    camera_ = OrbitCamera{};
    const auto box = renderer_->splats().splat_box();
    camera_.fit(box[0], box[1]);
    camera_.azimuth = o_.azimuth;
    camera_.elevation = o_.elevation;
    if (o_.distance) camera_.distance = *o_.distance;
  }

  // Compute: a finished re-solve replaces u; input events move the camera.
  void update_solve() {
    try {
      auto [u, report] = solving_.get();
      const bool polish = polishing_;
      polishing_ = false;
      if (polish) {
        polish_seconds_ = since(solve_start_);
        polish_report_ = report;
      } else {
        solve_report_ = report;
        solve_seconds_ = since(solve_start_);
        polish_seconds_ = 0;
      }
      if (!u.data.empty()) {  // a polish with nothing to finish returns none
        input_.u = std::move(u);
        input_.params = solve_params_;
        upload_u();
        regenerate();
        mesh_dirty_ = caster_dirty_ = slices_dirty_ = true;
        ++u_version_;  // the mesh, the ray caster and the slices follow the new u
      }
    } catch (const std::exception& e) {  // bad parameters (e.g. too wide a lowpass), device out of memory
      status_ = std::string("re-solve failed: ") + e.what();
    }
    // A change made while solving: solve again; else finish the re-solve
    // that stopped at the display's tolerance (SolverParams::resolve_tol).
    const bool again = resolve_pending_ && edit_ && !same_params(*edit_, input_.params);
    resolve_pending_ = false;
    if (again) start_solve(*edit_);
    else start_polish();
  }

  // The last re-solve carried on to the solver's tolerance in the
  // background (VariationalClassifier::polish: one PCG iteration, about a
  // third of a re-solve); a slider moved meanwhile waits for it.
  void start_polish() {
    if (solving_.valid() || !input_.classifier || !input_.classifier->polishable()) return;
    polishing_ = true;
    solve_start_ = Clock::now();
    solving_ = std::async(std::launch::async, [this] {
      SolveReport report;
      Volume u = input_.classifier->polish(&report);
      return std::make_pair(std::move(u), report);
    });
  }

  // 3D+t: show frame k of the opacity sequence (new splats, mesh, ray
  // caster and slices; the splat renderer's buffers are re-used).
  void set_frame(std::size_t k) {
    if (input_.sequence.empty() || k >= input_.sequence.size() || solving_.valid()) return;
    input_.frame = k;
    input_.u.data = input_.sequence[k].data;
    if (k < input_.bmode_sequence.size()) input_.bmode.data = input_.bmode_sequence[k].data, field_stale_ = true;
    upload_u();
    regenerate();
    mesh_dirty_ = caster_dirty_ = slices_dirty_ = true;
    ++u_version_;
    last_frame_switch_ = Clock::now();
  }

  // Playing: the next frame once 1 / fps has passed (scripted runs: every
  // drawn frame).
  void advance_sequence() {
    if (input_.sequence.empty() || !playing_ || play_fps_ <= 0) return;
    if (o_.frames == 0 && since(last_frame_switch_) < 1.0 / play_fps_) return;
    set_frame((input_.frame + 1) % input_.sequence.size());
  }

  // The depth colour map's range as a bar (near left, deep right), in the
  // panel under the colour choice: the same colours as the shaders
  // (depth_colour in host/image.hpp).
  void depth_legend() {
    char near_text[32], far_text[32];
    std::snprintf(near_text, sizeof near_text, "%.1f mm", double(settings_.depth_lo));
    std::snprintf(far_text, sizeof far_text, "%.1f mm", double(settings_.depth_hi));
    ImGui::TextUnformatted(near_text);
    ImGui::SameLine();
    const float w = std::max(40.0f, ImGui::GetContentRegionAvail().x - ImGui::CalcTextSize(far_text).x - 8.0f);
    const float h = ImGui::GetTextLineHeight();
    const ImVec2 p = ImGui::GetCursorScreenPos();
    ImDrawList* dl = ImGui::GetWindowDrawList();
    constexpr int steps = 16;
    for (int k = 0; k < steps; ++k) {
      const Rgb a = depth_colour(double(k) / steps), b = depth_colour(double(k + 1) / steps);
      const ImU32 ca = IM_COL32(a.r, a.g, a.b, 255), cb = IM_COL32(b.r, b.g, b.b, 255);
      dl->AddRectFilledMultiColor(ImVec2(p.x + w * k / steps, p.y), ImVec2(p.x + w * (k + 1) / steps, p.y + h), ca, cb,
                                  cb, ca);
    }
    ImGui::Dummy(ImVec2(w, h));
    if (ImGui::IsItemHovered()) ImGui::SetTooltip("depth along the beam: light near the transducer, dark deep");
    ImGui::SameLine();
    ImGui::TextUnformatted(far_text);
  }

  void sequence_controls() {
    int k = int(input_.frame);
    const int n = int(input_.sequence.size());
    ImGui::Text("frame %d (0 to %d)", k, n - 1);
    if (ImGui::SliderInt("frame", &k, 0, n - 1)) set_frame(std::size_t(k));
    if (ImGui::Button(playing_ ? "pause" : "play")) playing_ = !playing_, last_frame_switch_ = Clock::now();
    ImGui::SameLine();
    if (ImGui::Button("<")) set_frame((input_.frame + std::size_t(n) - 1) % std::size_t(n));
    ImGui::SameLine();
    if (ImGui::Button(">")) set_frame((input_.frame + 1) % std::size_t(n));
    ImGui::SliderFloat("frames/s", &play_fps_, 1.0f, 30.0f, "%.0f");
  }

  static bool same_params(const VariationalParams& a, const VariationalParams& b) {
    return a.v_iso == b.v_iso && a.alpha == b.alpha && a.beta == b.beta && a.gamma == b.gamma && a.omega == b.omega &&
           a.delta == b.delta && a.epsilon == b.epsilon && a.kappa == b.kappa && a.sigma_mm == b.sigma_mm &&
           a.shell_shift_mm == b.shell_shift_mm;
  }

  void start_solve(const VariationalParams& p) {
    if (solving_.valid()) {
      resolve_pending_ = true;
      return;
    }
    solve_params_ = p;
    solve_start_ = Clock::now();
    // The worker uses the runtime alone: the main thread does no OpenCL
    // work until the future is ready (regenerate is held back).
    solving_ = std::async(std::launch::async, [this, p] {
      SolveReport report;
      Volume u = reclassify(rt_, input_, p, nullptr, &report);  // warm: from the last solve
      return std::make_pair(std::move(u), report);
    });
  }

  void update() {
    if (solving_.valid() && solving_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) update_solve();
    advance_sequence();
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

  // The 3-D scene (splats, mesh or ray-cast image) into the viewport (x, y from the bottom).
  void draw_scene(int x, int y, int w, int h) {
    glEnable(GL_SCISSOR_TEST);
    glScissor(x, y, w, h);
    glViewport(x, y, w, h);
    switch (mode_) {
      case ViewRenderer::Splats: stats_ = renderer_->draw(camera_, settings_, w, h); break;
      case ViewRenderer::Mesh: draw_mesh(w, h); break;
      case ViewRenderer::Raycast: draw_raycast(w, h); break;
    }
    glDisable(GL_SCISSOR_TEST);
  }

  void save_framebuffer(const std::string& path, int fw, int fh) {
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

  // Draw: the window (panel, 3-D view, slices). A screenshot without the
  // panel (S, or --screenshot without --screenshot-panel) is the 3-D view
  // alone at the window's size, drawn just for it.
  void render(const std::string& screenshot_path) {
    int fw = 0, fh = 0, ww = 0, wh = 0;
    glfwGetFramebufferSize(gl_->window(), &fw, &fh);
    glfwGetWindowSize(gl_->window(), &ww, &wh);
    if (fw <= 0 || fh <= 0 || ww <= 0 || wh <= 0) return;  // minimised
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    const bool with_panel = o_.screenshot_panel && !screenshot_path.empty();
    std::string path = screenshot_path;
    if (path.empty() && screenshot_request_) {
      char name[64];
      std::snprintf(name, sizeof name, "softshell-view-%03d.png", screenshots_++);
      path = name;
    }
    screenshot_request_ = false;
    if (!path.empty() && !with_panel) {
      draw_scene(0, 0, fw, fh);
      save_framebuffer(path, fw, fh);
    }

    layout_ = window_layout(float(ww), float(wh));
    const float sx = float(fw) / float(ww), sy = float(fh) / float(wh);
    const Rect& v = layout_.view;
    const int vx = int(std::lround(v.x * sx)), vw = int(std::lround(v.w * sx)), vh = int(std::lround(v.h * sy));
    const int vy = fh - int(std::lround((v.y + v.h) * sy));
    glViewport(0, 0, fw, fh);
    // The panel's and the strip's background: cleared here (a memset), not
    // blended by ImGui over half a million pixels (llvmpipe fills in software).
    glClearColor(kPanelGrey, kPanelGrey, kPanelGrey, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT);
    const auto t0 = Clock::now();
    if (vw > 0 && vh > 0) {
      draw_scene(vx, vy, vw, vh);
      if (show_planes_) draw_planes(vx, vy, vw, vh);
    }
    glFinish();  // honest frame times (llvmpipe would otherwise queue)
    const double ms = 1000.0 * since(t0);
    // The panel's running frame time leaves out the first frame (lists, textures, ray cast built).
    if (++drawn_ > 1) frame_ms_ = frame_ms_ == 0 ? ms : 0.9 * frame_ms_ + 0.1 * ms;
    glViewport(0, 0, fw, fh);
    draw_panel();
    if (!path.empty() && with_panel) {
      save_framebuffer(path, fw, fh);
      if (!o_.quiet) print_layout();
    }
  }

  // Where things are in the window, for scripts and tests.
  void print_layout() const {
    const Rect& v = layout_.view;
    std::printf("view: 3-D view at %.0f,%.0f %.0fx%.0f\n", v.x, v.y, v.w, v.h);
    for (int k = 0; k < 3; ++k) {
      const Rect& r = slice_image_[k];
      std::printf("view: slice %s %c = %d, image at %.0f,%.0f %.0fx%.0f (%dx%d voxels)\n", kSliceNames[k],
                  "xyz"[kAxes[k][2]], cursor_[kAxes[k][2]], r.x, r.y, r.w, r.h, int(input_.u.dims[kAxes[k][0]]),
                  int(input_.u.dims[kAxes[k][1]]));
    }
    if (hist_rect_.w > 0)
      std::printf("view: histogram at %.0f,%.0f %.0fx%.0f, range [%.9g, %.9g], marker %.9g\n", hist_rect_.x,
                  hist_rect_.y, hist_rect_.w, hist_rect_.h, hist_lo_, hist_hi_, hist_marker_);
    std::fflush(stdout);
  }

  // The slice planes' outlines in the 3-D view, in their axes' colours.
  void draw_planes(int x, int y, int w, int h) {
    const Volume& u = input_.u;
    std::array<float, 3> lo, hi, at;
    for (int a = 0; a < 3; ++a) {
      lo[a] = float(u.origin[a]);
      hi[a] = float(u.origin[a] + u.spacing[a] * double(u.dims[a] - 1));
      at[a] = float(u.origin[a] + u.spacing[a] * double(cursor_[a]));
    }
    std::vector<float> verts;
    for (int k = 0; k < 3; ++k) {
      const int au = kAxes[k][0], av = kAxes[k][1], an = kAxes[k][2];
      const float cu[4] = {lo[au], hi[au], hi[au], lo[au]}, cv[4] = {lo[av], lo[av], hi[av], hi[av]};
      for (int e = 0; e < 4; ++e)
        for (int end = 0; end < 2; ++end) {
          float p[3];
          p[au] = cu[(e + end) % 4], p[av] = cv[(e + end) % 4], p[an] = at[an];
          verts.insert(verts.end(), p, p + 3);
        }
    }
    glEnable(GL_SCISSOR_TEST);
    glScissor(x, y, w, h);
    glViewport(x, y, w, h);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    glUseProgram(line_program_);
    const glm::mat4 mvp = camera_.projection(float(w) / float(h)) * camera_.view();
    glUniformMatrix4fv(glGetUniformLocation(line_program_, "u_mvp"), 1, GL_FALSE, &mvp[0][0]);
    glBindVertexArray(line_vao_);
    glBindBuffer(GL_ARRAY_BUFFER, line_vbo_);
    glBufferSubData(GL_ARRAY_BUFFER, 0, GLsizeiptr(verts.size() * sizeof(float)), verts.data());
    for (int k = 0; k < 3; ++k) {
      const glm::vec3 c = kAxisColourGl[kAxes[k][2]];
      glUniform3f(glGetUniformLocation(line_program_, "u_colour"), c.x, c.y, c.z);
      glDrawArrays(GL_LINES, 8 * k, 8);
    }
    glBindBuffer(GL_ARRAY_BUFFER, 0);
    glBindVertexArray(0);
    glUseProgram(0);
    glDisable(GL_SCISSOR_TEST);
  }

  // The histogram of the scanned voxels of what the classifier sees (or of
  // the B-mode volume, or of u for an opacity volume alone): 128 bins.
  void build_histogram() {
    const Volume* v = input_.classified ? &input_.data : !input_.bmode.data.empty() ? &input_.bmode : &input_.u;
    const std::vector<std::uint8_t>* mask = input_.classified && !input_.mask.empty() ? &input_.mask : nullptr;
    double lo = 1e300, hi = -1e300;
    for (std::size_t i = 0; i < v->data.size(); ++i)
      if (!mask || (*mask)[i]) lo = std::min(lo, double(v->data[i])), hi = std::max(hi, double(v->data[i]));
    if (!(lo <= hi)) lo = 0, hi = 1;
    if (hi <= lo) hi = lo + 1;
    hist_lo_ = lo, hist_hi_ = hi;
    hist_.assign(128, 0.0f);
    std::vector<double> counts(128, 0.0);
    for (std::size_t i = 0; i < v->data.size(); ++i)
      if (!mask || (*mask)[i]) counts[std::min<std::size_t>(127, std::size_t((v->data[i] - lo) / (hi - lo) * 128.0))] += 1;
    double top = 0;
    for (double c : counts) top = std::max(top, std::log10(1.0 + c));
    for (int b = 0; b < 128; ++b) hist_[b] = top > 0 ? float(std::log10(1.0 + counts[b]) / top) : 0.0f;
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
    slice_views();
    view_overlays();
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
  }

  // What the 3-D view's drawing order is, in words.
  std::string order_text() const {
    if (stats_.list < 0) return "drawn back to front (exact sort by distance)";
    return std::string("drawn back to front along ") + "xyz"[stats_.list / 2] + " (presorted)";
  }

  static constexpr ImGuiWindowFlags kFixed = ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize |
                                             ImGuiWindowFlags_NoCollapse | ImGuiWindowFlags_NoSavedSettings |
                                             ImGuiWindowFlags_NoBackground;

  void panel() {
    ImGui::SetNextWindowPos(ImVec2(layout_.panel.x, layout_.panel.y), ImGuiCond_Always);
    ImGui::SetNextWindowSize(ImVec2(layout_.panel.w, layout_.panel.h), ImGuiCond_Always);
    ImGui::Begin("softshell", nullptr, kFixed | ImGuiWindowFlags_NoTitleBar);
    ImGui::PushItemWidth(std::floor(0.42f * layout_.panel.w));
    const double fps = frame_ms_ > 0 ? 1000.0 / frame_ms_ : 0.0;
    if (mode_ == ViewRenderer::Splats) {
      ImGui::Text("%zu splats, %.1f ms/frame (%.0f fps)", stats_.splats, frame_ms_, fps);
      ImGui::TextDisabled("%s", order_text().c_str());
    } else if (mode_ == ViewRenderer::Mesh) {
      ImGui::Text("%zu triangles, %.1f ms/frame (%.0f fps)", mesh_triangles_, frame_ms_, fps);
      ImGui::TextDisabled("surface u = %.2f, extracted in %.1f ms", mesh_extracted_level_, mesh_ms_);
    } else {
      ImGui::Text("ray cast %dx%d: %.0f ms (kernel %.0f ms)", ray_w_, ray_h_, ray_ms_, ray_kernel_ms_);
      ImGui::TextDisabled("re-cast only when the view or settings change");
      if (!ray_error_.empty()) ImGui::TextColored(ImVec4(1.0f, 0.5f, 0.4f, 1.0f), "%s", ray_error_.c_str());
    }
    ImGui::TextDisabled("drag: rotate, right-drag: pan, wheel: zoom\nclick a slice: move the cursor, wheel: page\nS: screenshot, R: reset view, Esc: quit\naxes: x red, y green, z (depth) blue");
    if (!status_.empty()) ImGui::TextWrapped("%s", status_.c_str());

    if (!input_.sequence.empty() && ImGui::CollapsingHeader("Sequence", ImGuiTreeNodeFlags_DefaultOpen))
      sequence_controls();
    if (ImGui::CollapsingHeader("Data and isovalue", ImGuiTreeNodeFlags_DefaultOpen)) histogram();

    if (ImGui::CollapsingHeader("Classification", ImGuiTreeNodeFlags_DefaultOpen)) classification();

    if (ImGui::CollapsingHeader("Rendering", ImGuiTreeNodeFlags_DefaultOpen)) {
      const char* renderers[] = {"oriented splats", "isotropic splats", "surface mesh (Marching Cubes)", "ray casting"};
      int renderer = mode_ == ViewRenderer::Mesh      ? 2
                     : mode_ == ViewRenderer::Raycast ? 3
                     : settings_.method == SplatMethod::Isotropic ? 1
                                                                  : 0;
      preset_menu();
      if (ImGui::Combo("renderer", &renderer, renderers, 4)) {
        mode_ = renderer == 2 ? ViewRenderer::Mesh : renderer == 3 ? ViewRenderer::Raycast : ViewRenderer::Splats;
        if (renderer < 2) settings_.method = renderer == 1 ? SplatMethod::Isotropic : SplatMethod::Oriented;
        frame_ms_ = 0, drawn_ = 0;
        slices_dirty_ = true;  // the contour follows the renderer's level
      }
      if (mode_ == ViewRenderer::Mesh) {
        ImGui::SliderFloat("surface at u", &mesh_level_, 0.02f, 0.98f, "%.2f");
        if (ImGui::IsItemDeactivatedAfterEdit()) mesh_dirty_ = slices_dirty_ = true;  // re-extracted on release
        if (mesh_triangles_ == 0 && !mesh_dirty_) ImGui::TextDisabled("no surface at this level");
      } else if (mode_ == ViewRenderer::Raycast) {
        ImGui::SliderFloat("opacity cut", &ray_cut_, 0.0f, 0.9f, "%.2f");
        if (ImGui::IsItemDeactivatedAfterEdit()) slices_dirty_ = true;
      } else {
        splat_controls();
      }
      ImGui::SliderFloat("light left/right", &settings_.light_azimuth, -90.0f, 90.0f, "%.0f deg");
      ImGui::SliderFloat("light up/down", &settings_.light_elevation, -90.0f, 90.0f, "%.0f deg");
      int cmap = settings_.depth_colour ? 1 : 0;
      ImGui::RadioButton("one colour", &cmap, 0);
      ImGui::SameLine();
      ImGui::RadioButton("colour by depth", &cmap, 1);
      settings_.depth_colour = cmap == 1;
      if (settings_.depth_colour && mode_ == ViewRenderer::Raycast) ImGui::TextDisabled("(the ray caster draws one colour)");
      if (settings_.depth_colour && mode_ != ViewRenderer::Raycast) depth_legend();
      ImGui::ColorEdit3("colour", &settings_.colour.x, ImGuiColorEditFlags_NoInputs);
      ImGui::SameLine();
      ImGui::ColorEdit3("background", &settings_.background.x, ImGuiColorEditFlags_NoInputs);
      ImGui::Checkbox("scale bar and axes", &show_scale_);
      ImGui::SameLine();
      ImGui::Checkbox("slice planes", &show_planes_);
    }

    if (ImGui::CollapsingHeader("Cut away", ImGuiTreeNodeFlags_DefaultOpen)) {
      const glm::vec3 lo = settings_.crop_lo, hi = settings_.crop_hi;
      ImGui::DragFloatRange2("crop x", &settings_.crop_lo.x, &settings_.crop_hi.x, 0.005f, 0.0f, 1.0f, "%.2f");
      ImGui::DragFloatRange2("crop y", &settings_.crop_lo.y, &settings_.crop_hi.y, 0.005f, 0.0f, 1.0f, "%.2f");
      ImGui::DragFloatRange2("crop z (depth)", &settings_.crop_lo.z, &settings_.crop_hi.z, 0.005f, 0.0f, 1.0f, "%.2f");
      const char* planes[] = {"off", "facing the camera", "across x", "across y", "across z (depth)"};
      ImGui::Combo("clip plane", &clip_mode_, planes, 5);
      if (clip_mode_ != 0) {
        ImGui::SliderFloat("clip position", &clip_offset_, -1.0f, 1.0f, "%.2f");
        ImGui::Checkbox("keep the other side", &clip_flip_);
        if (mode_ != ViewRenderer::Splats) ImGui::TextDisabled("(the clip plane cuts splats only)");
      }
      apply_clip();
      if (ImGui::Button("reset cuts")) {
        settings_.crop_lo = glm::vec3(0.0f), settings_.crop_hi = glm::vec3(1.0f);
        clip_mode_ = 0;
      }
      if (lo != settings_.crop_lo || hi != settings_.crop_hi) slices_dirty_ = true;
    }

    if (ImGui::CollapsingHeader("Slices", ImGuiTreeNodeFlags_DefaultOpen)) {
      for (int a = 0; a < 3; ++a) {
        const char* names[3] = {"cursor x (sagittal)", "cursor y (coronal)", "cursor z (axial)"};
        if (ImGui::SliderInt(names[a], &cursor_[a], 0, int(input_.u.dims[a]) - 1)) slices_dirty_ = true;
      }
      const bool b = !input_.bmode.data.empty();
      if (b && ImGui::SliderFloat("u overlay", &overlay_, 0.0f, 1.0f, "%.2f")) slices_dirty_ = true;
      if (ImGui::Checkbox("contour of the drawn surface", &contour_)) slices_dirty_ = true;
      if (!b) ImGui::TextDisabled("no B-mode volume: the slices show u (view IN --volume V)");
    }

    if (ImGui::CollapsingHeader("Save", ImGuiTreeNodeFlags_DefaultOpen)) {
      ImGui::InputText("file prefix", save_prefix_, sizeof save_prefix_);
      const std::string prefix = save_prefix_;
      if (ImGui::Button("save u")) guarded([&] { save_u(prefix + "-u.nrrd"); });
      ImGui::SameLine();
      if (ImGui::Button("save mesh")) guarded([&] { save_mesh(prefix + "-mesh.ply"); });
      ImGui::SameLine();
      if (ImGui::Button("save parameters")) guarded([&] { save_params(prefix + "-params.txt"); });
      ImGui::TextDisabled("u: float NRRD; mesh: PLY of the surface at u = %.2f;\nparameters: softshell view/classify --params", mesh_level_);
    }
    ImGui::TextDisabled("splat generation %.1f ms", generate_ms_);
    ImGui::PopItemWidth();
    ImGui::End();
  }

  template <typename F>
  void guarded(F&& f) {
    try {
      f();
    } catch (const std::exception& e) {
      status_ = e.what();
    }
  }

  void classification() {
    if (!input_.classified) {
      ImGui::TextWrapped("The input is an opacity volume; open the raw ultrasound volume to re-classify.");
      return;
    }
    if (!edit_.has_value()) edit_ = input_.params;
    VariationalParams& p = *edit_;
    const IntensityMap map = input_.data.intensity_map();
    float iso = float(map.from_unit(p.v_iso));
    const float lo = float(map.from_unit(0.0)), hi = float(map.from_unit(1.0));
    bool release = false;
    if (ImGui::SliderFloat("isovalue", &iso, lo, hi, "%.1f")) p.v_iso = map.to_unit(iso);
    release |= ImGui::IsItemDeactivatedAfterEdit();
    release |= slider("sigma (lowpass, mm)", p.sigma_mm, 0.0f, 4.0f, false);
    release |= slider("alpha (isovalue)", p.alpha, 0.0f, 10.0f);
    release |= slider("beta (along the surface)", p.beta, 0.0f, 20.0f);
    release |= slider("gamma (indication)", p.gamma, 0.01f, 20.0f);
    release |= slider("omega (v vs lowpassed v)", p.omega, 0.0f, 1.0f, false);
    release |= slider("delta (flat indication)", p.delta, 0.001f, 1.0f);
    release |= slider("epsilon (gradient floor)", p.epsilon, 1e-6f, 10.0f);
    release |= slider("kappa (smoothness)", p.kappa, 0.0f, 10.0f);
    release |= slider("shell shift (mm)", p.shell_shift_mm, 0.0f, 2.0f, false);
    ImGui::TextDisabled("releasing a slider re-solves (warm start)");
    if (release) start_solve(p);
    if (solving_.valid()) {
      if (polishing_) ImGui::Text("polishing the last re-solve ... %.1f s", since(solve_start_));
      else ImGui::Text("solving ... %.1f s", since(solve_start_));
      ImGui::ProgressBar(-1.0f * float(ImGui::GetTime()), ImVec2(-1, 0), "multigrid PCG");
    } else if (ImGui::Button("re-solve now")) {
      start_solve(p);
    }
    if (solve_seconds_ > 0)
      ImGui::Text("last solve: %.2f s, %d iterations, residual %.1e%s", solve_seconds_, solve_report_.cycles,
                  solve_report_.residuals.empty() ? 0.0 : solve_report_.residuals.back(),
                  solve_report_.converged ? "" : " (not converged)");
    if (polish_seconds_ > 0 && !polish_report_.residuals.empty())
      ImGui::Text("then polished: %.2f s, %d iterations, residual %.1e%s", polish_seconds_, polish_report_.cycles,
                  polish_report_.residuals.back(), polish_report_.converged ? "" : " (not converged)");
  }

  // The histogram (log counts) with the isovalue (or, for an opacity volume,
  // the splat threshold) marked; dragging on it moves the marker, releasing
  // re-solves (or regenerates the splats).
  void histogram() {
    const bool iso = input_.classified;
    const IntensityMap map = input_.data.intensity_map();
    if (iso && !edit_) edit_ = input_.params;
    hist_marker_ = iso ? map.from_unit(edit_->v_iso) : double(params_.threshold);
    const bool marker = iso || (input_.bmode.data.empty() && mode_ == ViewRenderer::Splats);
    ImGui::TextDisabled("%s (log)%s", iso ? "scanned voxels" : !input_.bmode.data.empty() ? "B-mode voxels" : "u",
                        marker ? (iso ? "; drag the isovalue" : "; drag the threshold") : "");
    const ImVec2 p0 = ImGui::GetCursorScreenPos();
    const float w = std::max(50.0f, ImGui::GetContentRegionAvail().x), h = 80.0f;
    hist_rect_ = {p0.x, p0.y, w, h};
    ImGui::InvisibleButton("histogram", ImVec2(w, h));
    ImDrawList* dl = ImGui::GetWindowDrawList();
    dl->AddRectFilled(p0, ImVec2(p0.x + w, p0.y + h), IM_COL32(30, 30, 34, 255));
    const int n = int(hist_.size());
    for (int b = 0; b < n; ++b) {
      const float x0 = p0.x + w * float(b) / float(n), x1 = p0.x + w * float(b + 1) / float(n);
      dl->AddRectFilled(ImVec2(x0, p0.y + h * (1.0f - hist_[b])), ImVec2(x1, p0.y + h), IM_COL32(150, 150, 160, 255));
    }
    if (marker) {
      if (ImGui::IsItemActive()) {
        const double f = std::clamp((ImGui::GetIO().MousePos.x - p0.x) / w, 0.0f, 1.0f);
        hist_marker_ = hist_lo_ + f * (hist_hi_ - hist_lo_);
        if (iso) edit_->v_iso = map.to_unit(hist_marker_);
        else params_.threshold = std::clamp(float(hist_marker_), 0.02f, 0.9f);
      }
      if (ImGui::IsItemDeactivated()) {
        if (iso) start_solve(*edit_);
        else if (!solving_.valid()) regenerate(), slices_dirty_ = true;
      }
      const float x = p0.x + w * float(std::clamp((hist_marker_ - hist_lo_) / (hist_hi_ - hist_lo_), 0.0, 1.0));
      dl->AddRectFilled(ImVec2(x - 1, p0.y), ImVec2(x + 1, p0.y + h), kIsoColour);
    }
    ImGui::TextDisabled("%.4g", hist_lo_);
    ImGui::SameLine(std::max(0.0f, w - 60.0f));
    ImGui::TextDisabled("%10.4g", hist_hi_);
    if (marker) ImGui::Text("%s %.4g", iso ? "isovalue" : "threshold", hist_marker_);
  }

  // The level the slices' contour shows: the current renderer's.
  float contour_level() const {
    return mode_ == ViewRenderer::Mesh ? mesh_level_ : mode_ == ViewRenderer::Raycast ? ray_cut_ : params_.threshold;
  }

  // The three slices as RGBA textures: B-mode grey (or u), u overlaid in
  // orange with the overlay opacity, the contour of u at the drawn level in yellow.
  void update_slices() {
    const Volume& u = input_.u;
    const bool b = !input_.bmode.data.empty();
    const IntensityMap map = b ? input_.bmode.intensity_map() : IntensityMap{};
    const float level = contour_level();
    for (int k = 0; k < 3; ++k) {
      const int au = kAxes[k][0], av = kAxes[k][1], an = kAxes[k][2];
      const int nu = int(u.dims[au]), nv = int(u.dims[av]);
      std::vector<std::uint8_t> px(std::size_t(nu) * nv * 4);
      auto index = [&](int i, int j) {
        std::size_t c[3];
        c[au] = std::size_t(i), c[av] = std::size_t(j), c[an] = std::size_t(cursor_[an]);
        return u.index(c[0], c[1], c[2]);
      };
      for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
          const std::size_t idx = index(i, j);
          const float uu = u.data[idx];
          const float g = b ? float(std::clamp(map.to_unit(input_.bmode.data[idx]), 0.0, 1.0)) : std::clamp(uu, 0.0f, 1.0f);
          float rgb[3] = {g, g, g};
          if (b) {
            const float a = overlay_ * std::clamp(uu, 0.0f, 1.0f);
            const float col[3] = {1.0f, 0.45f, 0.05f};
            for (int c = 0; c < 3; ++c) rgb[c] = g * (1.0f - a) + col[c] * a;
          }
          if (contour_) {
            const bool in = uu >= level;
            bool edge = false;
            if (i + 1 < nu) edge |= (u.data[index(i + 1, j)] >= level) != in;
            if (j + 1 < nv) edge |= (u.data[index(i, j + 1)] >= level) != in;
            if (edge) rgb[0] = 1.0f, rgb[1] = 0.95f, rgb[2] = 0.2f;
          }
          std::uint8_t* q = &px[(std::size_t(j) * nu + i) * 4];
          for (int c = 0; c < 3; ++c) q[c] = std::uint8_t(std::lround(255.0f * std::clamp(rgb[c], 0.0f, 1.0f)));
          q[3] = 255;
        }
      glBindTexture(GL_TEXTURE_2D, slice_textures_[k]);
      glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, nu, nv, 0, GL_RGBA, GL_UNSIGNED_BYTE, px.data());
      glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    }
    glBindTexture(GL_TEXTURE_2D, 0);
    slices_dirty_ = false;
  }

  // The slice strip under the 3-D view: each pane its slice (square mm),
  // the cursor's other two planes as lines in their colours, the crop box.
  void slice_views() {
    if (slices_dirty_) update_slices();
    const Volume& u = input_.u;
    ImGui::SetNextWindowPos(ImVec2(layout_.strip.x, layout_.strip.y), ImGuiCond_Always);
    ImGui::SetNextWindowSize(ImVec2(layout_.strip.w, layout_.strip.h), ImGuiCond_Always);
    ImGui::PushStyleVar(ImGuiStyleVar_WindowPadding, ImVec2(0, 0));
    ImGui::Begin("slices", nullptr, kFixed | ImGuiWindowFlags_NoTitleBar | ImGuiWindowFlags_NoScrollbar |
                                        ImGuiWindowFlags_NoScrollWithMouse | ImGuiWindowFlags_NoBringToFrontOnFocus);
    ImDrawList* dl = ImGui::GetWindowDrawList();
    for (int k = 0; k < 3; ++k) {
      const int au = kAxes[k][0], av = kAxes[k][1], an = kAxes[k][2];
      const Rect& pane = layout_.pane[k];
      const float label_h = ImGui::GetTextLineHeightWithSpacing() + 2.0f;
      char label[96];
      std::snprintf(label, sizeof label, "%s  %c = %d (%.1f mm)", kSliceNames[k], "xyz"[an], cursor_[an],
                    u.origin[an] + u.spacing[an] * cursor_[an]);
      dl->AddText(ImVec2(pane.x + 6, pane.y + 2), kAxisColour[an], label);
      // The slice in square mm, fitted into the pane below the label.
      const float mw = float(u.spacing[au] * u.dims[au]), mh = float(u.spacing[av] * u.dims[av]);
      const float aw = pane.w - 8.0f, ah = pane.h - label_h - 4.0f;
      const float scale = std::max(0.0f, std::min(aw / mw, ah / mh));
      Rect r{std::floor(pane.x + 4.0f + 0.5f * (aw - mw * scale)), std::floor(pane.y + label_h + 0.5f * (ah - mh * scale)),
             std::floor(mw * scale), std::floor(mh * scale)};
      slice_image_[k] = r;
      if (r.w < 2 || r.h < 2) continue;
      dl->AddImage(reinterpret_cast<ImTextureID>(static_cast<std::intptr_t>(slice_textures_[k])), ImVec2(r.x, r.y),
                   ImVec2(r.x + r.w, r.y + r.h));
      dl->AddRect(ImVec2(r.x - 1, r.y - 1), ImVec2(r.x + r.w + 1, r.y + r.h + 1), kAxisColour[an]);
      const float nu = float(u.dims[au]), nv = float(u.dims[av]);
      const auto px = [&](float i) { return r.x + (i + 0.5f) / nu * r.w; };
      const auto py = [&](float j) { return r.y + (j + 0.5f) / nv * r.h; };
      // The crop box, where it cuts.
      const glm::vec3 lo = settings_.crop_lo, hi = settings_.crop_hi;
      if (lo[au] > 0 || lo[av] > 0 || hi[au] < 1 || hi[av] < 1 || lo[an] > 0 || hi[an] < 1) {
        const bool inside = cursor_[an] >= lo[an] * (u.dims[an] - 1) - 0.5f && cursor_[an] <= hi[an] * (u.dims[an] - 1) + 0.5f;
        // On pixel centres, 2 px wide: one row or column fully covered (crisp, and found by tests).
        const auto snap = [](float t) { return std::floor(t) + 0.5f; };
        dl->AddRect(ImVec2(snap(px(lo[au] * (nu - 1))), snap(py(lo[av] * (nv - 1)))),
                    ImVec2(snap(px(hi[au] * (nu - 1))), snap(py(hi[av] * (nv - 1)))),
                    inside ? IM_COL32(245, 245, 245, 255) : IM_COL32(120, 120, 120, 255), 0.0f, 0, 2.0f);
      }
      // The cursor: the other two slices.
      dl->AddLine(ImVec2(px(float(cursor_[au])), r.y), ImVec2(px(float(cursor_[au])), r.y + r.h), kAxisColour[au] & 0xB0FFFFFF);
      dl->AddLine(ImVec2(r.x, py(float(cursor_[av]))), ImVec2(r.x + r.w, py(float(cursor_[av]))), kAxisColour[av] & 0xB0FFFFFF);
      ImGui::SetCursorScreenPos(ImVec2(r.x, r.y));
      ImGui::PushID(k);
      ImGui::InvisibleButton("slice", ImVec2(r.w, r.h));
      ImGui::PopID();
      if (ImGui::IsItemActive()) {  // click or drag: the cursor follows
        const ImVec2 m = ImGui::GetIO().MousePos;
        const int i = std::clamp(int((m.x - r.x) / r.w * nu), 0, int(nu) - 1);
        const int j = std::clamp(int((m.y - r.y) / r.h * nv), 0, int(nv) - 1);
        if (i != cursor_[au] || j != cursor_[av]) cursor_[au] = i, cursor_[av] = j, slices_dirty_ = true;
      }
      if (ImGui::IsItemHovered() && ImGui::GetIO().MouseWheel != 0.0f) {
        cursor_[an] = std::clamp(cursor_[an] + (ImGui::GetIO().MouseWheel > 0 ? 1 : -1), 0, int(u.dims[an]) - 1);
        slices_dirty_ = true;
      }
    }
    ImGui::End();
    ImGui::PopStyleVar();
  }

  // A scale bar (mm, at the depth of the view's centre) and an orientation
  // marker (the volume's axes as seen) in the 3-D view's corners.
  void view_overlays() {
    if (!show_scale_) return;
    const Rect& v = layout_.view;
    if (v.w < 120 || v.h < 80) return;
    ImDrawList* dl = ImGui::GetBackgroundDrawList();
    const float px_per_mm = v.h / (2.0f * camera_.distance * std::tan(0.5f * glm::radians(camera_.fov_y)));
    const float want = 0.2f * v.w / px_per_mm;  // a fifth of the view
    const float p10 = std::pow(10.0f, std::floor(std::log10(want)));
    const float len = want >= 5 * p10 ? 5 * p10 : want >= 2 * p10 ? 2 * p10 : p10;
    const float x0 = v.x + 20, y0 = v.y + v.h - 24, x1 = x0 + len * px_per_mm;
    const ImU32 white = IM_COL32(235, 235, 235, 255);
    dl->AddLine(ImVec2(x0, y0), ImVec2(x1, y0), white, 2.0f);
    dl->AddLine(ImVec2(x0, y0 - 5), ImVec2(x0, y0 + 5), white, 2.0f);
    dl->AddLine(ImVec2(x1, y0 - 5), ImVec2(x1, y0 + 5), white, 2.0f);
    char text[32];
    std::snprintf(text, sizeof text, "%g mm", len);
    dl->AddText(ImVec2(x0, y0 - 20), white, text);
    // Orientation: each axis' direction on the screen (y down).
    const ImVec2 c(v.x + v.w - 56, v.y + v.h - 50);
    const glm::vec3 right = camera_.right(), up = camera_.up();
    const char* names[3] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
      glm::vec3 e(0.0f);
      e[a] = 1.0f;
      const ImVec2 tip(c.x + 32.0f * glm::dot(e, right), c.y - 32.0f * glm::dot(e, up));
      dl->AddLine(c, tip, kAxisColour[a], 2.5f);
      dl->AddText(ImVec2(tip.x + 2, tip.y - 7), kAxisColour[a], names[a]);
    }
  }

  // The parameters of what is shown (host/params_file.hpp).
  ParamsFile current_params() const {
    ParamsFile f;
    if (!preset_.empty()) f.set("preset", preset_);
    if (input_.classified) {
      const VariationalParams& p = input_.params;  // of the u shown
      if (o_.iso_text == "auto" && p.v_iso == initial_v_iso_) f.set("iso", std::string("auto"));
      else f.set("iso", input_.data.intensity_map().from_unit(p.v_iso) + input_.fill);  // the file's units
      f.set("sigma", p.sigma_mm), f.set("alpha", p.alpha), f.set("beta", p.beta), f.set("gamma", p.gamma);
      f.set("omega", p.omega), f.set("delta", p.delta), f.set("epsilon", p.epsilon), f.set("kappa", p.kappa);
      f.set("shell_shift", p.shell_shift_mm);
    }
    f.set("renderer", std::string(mode_ == ViewRenderer::Mesh      ? "mc"
                                  : mode_ == ViewRenderer::Raycast ? "raycast"
                                  : settings_.method == SplatMethod::Isotropic ? "isosplat"
                                                                               : "splat"));
    f.set("threshold", double(params_.threshold));
    f.set("mesh_level", double(mesh_level_));
    f.set("light", std::vector<double>{settings_.light_azimuth, settings_.light_elevation});
    const auto rgb = [](glm::vec3 c) { return std::vector<double>{c.r, c.g, c.b}; };
    f.set("colour", rgb(settings_.colour));
    f.set("colour_map", std::string(settings_.depth_colour ? "depth" : "solid"));
    f.set("background", rgb(settings_.background));
    const glm::vec3 lo = settings_.crop_lo, hi = settings_.crop_hi;
    f.set("crop", std::vector<double>{lo.x, hi.x, lo.y, hi.y, lo.z, hi.z});
    f.set("view", std::vector<double>{camera_.azimuth, camera_.elevation});
    f.set("distance", double(camera_.distance));
    return f;
  }

  void saved(const std::string& what, const std::string& path) {
    status_ = "saved " + what + " " + path;
    if (!o_.quiet) std::cout << "view: saved " << what << ' ' << path << '\n';
  }

  void save_params(const std::string& path) {
    write_params_file(path, current_params());
    saved("parameters", path);
  }

  void save_u(const std::string& path) {
    WriteOptions w;
    w.type = ScalarType::Float32;
    write_volume(path, input_.u, w);
    saved("u", path);
  }

  void save_mesh(const std::string& path) {
    if (solving_.valid()) throw InputError("save mesh: wait for the re-solve to finish");
    const Mesh mesh = marching_cubes(rt_, input_.u, mesh_level_);
    if (mesh.triangle_count() == 0) throw InputError("save mesh: no surface at u = " + std::to_string(mesh_level_));
    write_ply_binary(path, mesh, ply_space_comment(input_.u));
    saved("mesh", path);
  }

  // The splat-only controls of the Rendering section.
  // Presets (host/presets.hpp): the rendering at once; the bone cue (the
  // classification part) re-solves when the viewer classified the data.
  void preset_menu() {
    const std::vector<Preset>& all = presets();
    int current = -1;
    for (std::size_t i = 0; i < all.size(); ++i)
      if (all[i].name == preset_) current = int(i);
    std::string items;
    for (const Preset& p : all) items += p.name + '\0';
    items += '\0';
    if (ImGui::Combo("preset", &current, items.c_str()) && current >= 0) apply_panel_preset(all[std::size_t(current)]);
    if (current >= 0 && ImGui::IsItemHovered()) ImGui::SetTooltip("%s", all[std::size_t(current)].what.c_str());
  }

  void apply_panel_preset(const Preset& p) {
    if (solving_.valid()) {
      status_ = "preset: wait for the re-solve to end";
      return;
    }
    preset_ = p.name;
    const SplatGaussian gaussian = params_.gaussian;
    const float threshold = params_.threshold;
    const SplatNormals normals = params_.normals;
    cli::apply_preset(p, settings_, params_, {});
    if (const std::string note = cli::settle_orientation(params_, !input_.bmode.data.empty(), false, "");
        !note.empty())
      status_ = "preset " + p.name + ": " + note;
    if (params_.gaussian != gaussian || params_.threshold != threshold || params_.normals != normals)
      regenerate(), slices_dirty_ = true;
    BoneCueMode mode = BoneCueMode::Off;
    parse_bone_cue_mode(p.bone_cue, mode);
    if (input_.classified && mode != input_.bone_cue) {
      const bool on = set_bone_cue(input_, mode);
      VariationalParams q = edit_ ? *edit_ : input_.params;
      q.edge_weight = input_.params.edge_weight;
      q.edge_reference = input_.params.edge_reference;
      if (edit_) edit_->edge_weight = q.edge_weight, edit_->edge_reference = q.edge_reference;
      status_ = std::string("preset ") + p.name + ": bone cue " + (on ? "on" : "off") + ", re-solving";
      start_solve(q);
    }
  }

  void splat_controls() {
    int normals = settings_.three_normals;
    ImGui::RadioButton("one normal", &normals, 0);
    ImGui::SameLine();
    ImGui::RadioButton("three normals (smoother)", &normals, 1);
    settings_.three_normals = normals != 0;
    int order = settings_.order == DrawOrder::Sort;
    ImGui::RadioButton("fast order", &order, 0);
    ImGui::SameLine();
    ImGui::RadioButton("exact order (sorted)", &order, 1);
    settings_.order = order ? DrawOrder::Sort : DrawOrder::Lists;
    bool shell = params_.centres == SplatCentres::Shell;
    if (ImGui::Checkbox("splats on the shell (no bands)", &shell) && !solving_.valid()) {
      params_.centres = shell ? SplatCentres::Shell : SplatCentres::Voxel;
      regenerate();
    }
    if (ImGui::Checkbox("ambient occlusion (soft shadows)", &params_.occlusion) && !solving_.valid()) regenerate();
    if (params_.occlusion) ImGui::SliderFloat("occlusion strength", &settings_.occlusion, 0.0f, 1.0f, "%.2f");
    ImGui::SliderFloat("threshold (u)", &params_.threshold, 0.02f, 0.9f, "%.2f");
    if (ImGui::IsItemDeactivatedAfterEdit() && !solving_.valid()) regenerate(), slices_dirty_ = true;
    // Splat orientation: the structure tensor of u, of the data (with a
    // B-mode volume) or grad u (the paper).
    int orient = static_cast<int>(params_.normals);
    const int before = orient;
    ImGui::TextUnformatted("splat orientation (docs/rendering.md)");
    ImGui::RadioButton("tensor of u", &orient, static_cast<int>(SplatNormals::Tensor));
    ImGui::SameLine();
    if (input_.bmode.data.empty()) ImGui::BeginDisabled();
    ImGui::RadioButton("data", &orient, static_cast<int>(SplatNormals::Data));
    if (input_.bmode.data.empty()) ImGui::EndDisabled();
    ImGui::SameLine();
    ImGui::RadioButton("grad u", &orient, static_cast<int>(SplatNormals::Gradient));
    if (orient != before && !solving_.valid()) {
      params_.normals = static_cast<SplatNormals>(orient);
      regenerate();
    }
  }

  // A weight's slider; true when it was released after a change.
  static bool slider(const char* name, double& v, float lo, float hi, bool logarithmic = true) {
    float f = float(v);
    if (ImGui::SliderFloat(name, &f, lo, hi, logarithmic ? "%.3g" : "%.3f",
                           logarithmic ? ImGuiSliderFlags_Logarithmic : ImGuiSliderFlags_None))
      v = f;
    return ImGui::IsItemDeactivatedAfterEdit();
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
  // The data orientation field of the B-mode frame shown (SplatNormals::Data),
  // built when first needed and again after a frame switch.
  cl::Buffer field_buffer_;
  bool field_stale_ = true;
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
  // 3D+t playback
  bool playing_ = false;
  float play_fps_ = 10.0f;
  Clock::time_point last_frame_switch_ = Clock::now();
  float ray_cut_ = 0.2f;  // the splats' epsilon, as `render --method raycast`
  std::vector<float> caster_key_, ray_key_;
  GLuint quad_program_ = 0, quad_vao_ = 0, ray_texture_ = 0;
  int ray_w_ = 0, ray_h_ = 0;
  double ray_ms_ = 0, ray_kernel_ms_ = 0;
  std::string ray_error_;
  OrbitCamera camera_;
  DrawStats stats_;
  double frame_ms_ = 0, generate_ms_ = 0, solve_seconds_ = 0, polish_seconds_ = 0;
  bool polishing_ = false;  // solving_ is a polish (start_polish)
  SolveReport polish_report_;
  bool screenshot_request_ = false;
  int screenshots_ = 0;
  bool keys_down_[GLFW_KEY_LAST + 1] = {};
  std::string status_;
  int clip_mode_ = 0;
  float clip_offset_ = 0.0f;
  bool clip_flip_ = false;
  std::optional<VariationalParams> edit_;
  std::string preset_;
  double initial_v_iso_ = 0;
  long drawn_ = 0;
  bool resolve_pending_ = false;
  // Layout, slices, histogram, overlays.
  Layout layout_;
  std::array<int, 3> cursor_{0, 0, 0};
  float overlay_;
  bool contour_ = true, slices_dirty_ = true, show_planes_ = true, show_scale_ = true;
  GLuint slice_textures_[3] = {0, 0, 0};
  std::array<Rect, 3> slice_image_{};
  GLuint line_program_ = 0, line_vao_ = 0, line_vbo_ = 0;
  std::vector<float> hist_;
  double hist_lo_ = 0, hist_hi_ = 1, hist_marker_ = 0;
  Rect hist_rect_;
  char save_prefix_[256] = {};
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
