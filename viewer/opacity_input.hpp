// What `render` and `view` draw: an opacity volume in [0, 1]. A raw
// ultrasound volume (integer samples, or floats outside [0, 1]) is classified
// first with the defaults of `softshell classify --iso auto` (auto isovalue,
// auto scanned-region mask, the variational classifier's default
// parameters). The raw data is kept so the viewer can re-solve.
#pragma once

#include "bone_cue.hpp"

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cl_runtime.hpp"
#include "variational.hpp"
#include "volume.hpp"

namespace softshell::viewer {

enum class InputKind { Auto, Opacity, Raw };

// True when the samples are floats within [0, 1] (an opacity volume).
bool looks_like_opacity(const Volume& v);

struct OpacityInput {
  Volume u;                          // opacity in [0, 1]
  // The B-mode volume as read (the slice views show it): the raw input when
  // classified here, `view --volume V` otherwise; empty: none (the slices show u).
  Volume bmode;
  bool classified = false;           // true when u was computed here
  // Only when classified: the data as the classifier saw it (unscanned voxels
  // filled), its mask (empty: all scanned), and the parameters used.
  Volume data;
  std::vector<std::uint8_t> mask;
  VariationalParams params;
  double iso = 0;                    // in the units of `data` (the file's, less `fill`)
  double fill = 0;                   // float data's unscanned fill, subtracted from `data` (host/mask.hpp)
  SolveReport report;
  std::string note;                  // one line for the user
  // The classifier behind u, kept for re-solves: a change of the pointwise
  // parameters (v_iso, alpha, gamma, omega, delta, epsilon) updates it in
  // place; beta or the lowpasses rebuild it.
  std::shared_ptr<VariationalClassifier> classifier;
  // A 3D+t opacity sequence (a 4-D NRRD of u, as `classify` writes one):
  // every frame's u; `u` is frame `frame`. Empty: one volume.
  std::vector<Volume> sequence;
  std::vector<Volume> bmode_sequence;  // the B-mode frames behind it (`view --volume`), or empty
  std::size_t frame = 0;
  int beam_axis = 2;                 // when classified: the beam axis the near-field step found
  BoneCueMode bone_cue = BoneCueMode::Off;
  // When classified: the shadow walls' edge weights (host/shadow_walls.hpp),
  // null with the paper's functional; combined with the bone cue's.
  std::shared_ptr<const std::vector<float>> walls;
};

// Reads `path` and returns its opacity (see above). `iso` is "auto" or a
// number in the file's units. Throws InputError for a file that is not a
// volume, and for an opacity volume with values outside [0, 1] forced by
// `kind`.
// `weights`: the classification parameters other than v_iso (default:
// VariationalParams{} with sigma 1 mm, as classify's defaults).
// A 3D+t file (a 4-D NRRD): an opacity sequence is read whole (`sequence`),
// starting on `frame` (default 0); a sequence of raw frames needs `frame`,
// which is then classified alone.
// `beam_axis` (0 x, 1 y, 2 z; -1: the data's own) is classify's --beam-axis.
OpacityInput load_opacity(Runtime& rt, const std::string& path, InputKind kind, const std::string& iso = "auto",
                          const VariationalParams* weights = nullptr,
                          std::optional<std::size_t> frame = std::nullopt, BoneCueMode bone_cue = BoneCueMode::Off,
                          int beam_axis = -1);

// The B-mode data behind an opacity volume (`view`/`render --volume V`), for
// the slice views and the splats' orientation by the data: into in.bmode (a
// sequence behind a sequence: frame by frame, in.bmode_sequence). Throws
// InputError when V's dims or frame count differ from the opacity's or its
// samples are not finite.
void attach_bmode(OpacityInput& in, const std::string& path);

// The bone cue's edge weights of a classified input for `mode` (classify's
// --bone-cue), into in.params.edge_weight; true when the cue is on. For a
// preset chosen in the panel: the next re-solve uses them.
bool set_bone_cue(OpacityInput& in, BoneCueMode mode);

// Re-solves with new parameters (normalised v_iso), warm: from `init` when
// given without sharpening, else from the last solve (its linear solution,
// VariationalClassifier::keep_resolve_start). Re-uses in.classifier when only pointwise parameters
// changed (docs/numerics.md, "Re-solving"), else builds a new one and keeps
// it there. Non-convergence is in `report`. Not thread-safe: one re-solve at
// a time.
Volume reclassify(Runtime& rt, OpacityInput& in, const VariationalParams& p, const Volume* init,
                  SolveReport* report);

}  // namespace softshell::viewer
