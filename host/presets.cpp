#include "presets.hpp"

namespace softshell {

const std::vector<Preset>& presets() {
  static const std::vector<Preset> p = [] {
    std::vector<Preset> v;
    Preset d;
    d.name = "default";
    d.what = "softshell's defaults: one skin-tone colour, light up-left, rim splats (no screen-door dots)";
    d.rim_gaussian = true;
    v.push_back(d);
    // Fetal face: obstetric surface rendering. Depth colour (near skin tones
    // to dark red-brown deep, as SlicerHeart's and the scanners' "sepia"
    // maps) separates the face from what lies behind it; the rim Gaussian
    // (larger, smoother splats) gives the soft skin look; light from the
    // upper left as on the scanners' default surface mode.
    Preset f = d;
    f.name = "face";
    f.what = "fetal face: depth colour (light near, red-brown deep), smooth rim splats, soft light from the upper left";
    f.depth_colour = true;
    f.rim_gaussian = true;
    f.specular = 0.10f;
    f.light_azimuth = -35.0f, f.light_elevation = 35.0f;
    // Oriented by the data: a head in fluid shades without u's blotches
    // (docs/rendering.md, "Orientation by the data": face phantoms 10.5 ->
    // 6.6 degrees); freehand sweeps' stripes are a bone preset's concern.
    f.orientation = "data";
    v.push_back(f);
    // Bone: the bone cue on (a bright echo over an acoustic shadow weights
    // the edge; docs/numerics.md), an ivory colour, crisp splats, a higher
    // threshold so only the shell's crest is drawn, light from above to
    // show the laminae's relief.
    Preset b = d;
    b.name = "bone";
    b.what = "bone: the bone cue on (bright echo over an acoustic shadow), ivory, crisp splats, light from above";
    b.bone_cue = "on";
    b.rim_gaussian = false;  // the paper's smaller splats: crisper edges on thin laminae
    b.colour = {0.95f, 0.92f, 0.82f};
    b.specular = 0.30f;
    b.threshold = 0.3f;
    b.light_azimuth = 0.0f, b.light_elevation = 50.0f;
    v.push_back(b);
    // Vessels: an anechoic lumen in brighter tissue; its wall is the same
    // dark-to-bright boundary the classifier draws. Red, smooth splats.
    Preset w = d;
    w.name = "vessels";
    w.what = "vessels: red, smooth rim splats, light from the upper right";
    w.colour = {0.80f, 0.16f, 0.13f};
    w.rim_gaussian = true;
    w.specular = 0.25f;
    w.light_azimuth = 30.0f, w.light_elevation = 30.0f;
    v.push_back(w);
    return v;
  }();
  return p;
}

const Preset* find_preset(const std::string& name) {
  for (const Preset& p : presets())
    if (p.name == name) return &p;
  return nullptr;
}

std::string preset_names() {
  std::string t;
  for (const Preset& p : presets()) t += (t.empty() ? "" : ", ") + p.name;
  return t;
}

}  // namespace softshell
