// Argument checks shared by every command (docs/robustness.md, "Arguments"):
//
//  - number options carry a range validator (real_range / int_range): the
//    value is parsed by the validator itself, so NaN, infinities, trailing
//    junk and values outside the option's meaning are refused at parse time
//    with "--name: must be a finite number in [lo, hi] (unit), got 'x'",
//    exit 2, before any file is read; `--help` shows the same range;
//  - options that take one of a list of words carry one_of(): the help text
//    and the error message print the same list;
//  - require_checked_numbers() runs after every command is registered and
//    gives a plain finiteness check to any floating-point option that has no
//    range yet (a safety net: tests/test_cli_args.cpp checks that every
//    floating-point option of every command has a range);
//  - check_output() checks an output path before any work: its extension
//    against the writer's, and that a file can be created there (a probe
//    temporary, removed at once; the real output is still written through a
//    temporary file and renamed into place when complete).
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell::cli {

enum class Ends { Closed, OpenLow, OpenHigh, Open };

// A real number in [lo, hi] (or with open ends); `unit` is printed after
// the range ("mm", "voxels").
CLI::Validator real_range(double lo, double hi, const std::string& unit = "", Ends ends = Ends::Closed);
// An integer in [lo, hi].
CLI::Validator int_range(long long lo, long long hi, const std::string& unit = "");
// One of `choices` (exact words).
CLI::Validator one_of(const std::vector<std::string>& choices);
// "a, b or c".
std::string choice_list(const std::vector<std::string>& choices);

// --beam-axis auto|x|y|z (classify, render, view), into `word` (default
// "auto"): the one registration the three commands share.
CLI::Option* add_beam_axis_option(CLI::App* sub, std::string& word, const std::string& help);
// Its word as an axis: "x", "y", "z" -> 0, 1, 2; "auto" -> -1 (the data's
// own axis). The option's one_of() has checked the word.
inline int beam_axis_option(const std::string& word) {
  return word == "x" ? 0 : word == "y" ? 1 : word == "z" ? 2 : -1;
}

// Safety net, after all commands are added: every option whose type is a
// floating-point number and has no range validator still refuses NaN and
// infinities.
void require_checked_numbers(CLI::App& app);
// The long names of the floating-point options of `sub` (and its option
// groups) without a range validator: empty when every one is checked.
std::vector<std::string> unranged_number_options(const CLI::App& sub);

// What writes an output path.
enum class OutputKind {
  Volume,     // write_volume: .nrrd, .mha, .mhd
  Png,        // write_png: .png
  Ply,        // write_ply: .ply
  Directory,  // a directory of outputs, created (with its parents) if missing
};
// Refuses (InputError, exit 2) an output whose extension the writer does not
// write (listing those it does) or that cannot be created: a missing or
// unwritable directory, a directory or device in its place. `option` names
// the option in the message ("-o", "--screenshot"). Creates nothing that
// outlives the call.
void check_output(const std::string& path, OutputKind kind, const std::string& option = "-o");

}  // namespace softshell::cli
