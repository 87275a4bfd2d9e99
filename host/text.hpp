// Small text helpers shared by the runtime, the readers and the CLI.
#pragma once

#include <string>

#include "volume.hpp"

namespace softshell {

std::string lower(std::string s);                 // ASCII lower case
std::string trim(const std::string& s);           // strips whitespace and NULs at both ends
std::string human_bytes(double bytes);            // "1.5 GiB"
std::string dims_text(const Dims3& d);            // "17x23x9"

}  // namespace softshell
