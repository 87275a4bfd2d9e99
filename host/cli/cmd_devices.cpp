// `softshell devices`: every OpenCL platform and device with its index, type,
// compute units, memory limits and OpenCL C version; marks the default.
#include <algorithm>
#include <iomanip>
#include <iostream>
#include <memory>

#include "cl_runtime.hpp"
#include "cli_common.hpp"
#include "error.hpp"
#include "text.hpp"

namespace softshell::cli {
namespace {

int run_devices(bool json) {
  const auto devices = enumerate_devices();
  int chosen = -1;
  std::string why;
  try {
    chosen = select_device("").index;
  } catch (const DeviceError& e) {
    why = e.what();  // $SOFTSHELL_DEVICE names nothing: still list what exists
  }
  if (json) {
    std::cout << "{\"default\": " << chosen << ", \"devices\": [";
    for (const auto& d : devices) {
      std::cout << (d.index ? ", " : "") << "{\"index\": " << d.index << ", \"type\": \"" << d.type
                << "\", \"name\": \"" << d.device_name << "\", \"platform\": \"" << d.platform_name
                << "\", \"vendor\": \"" << d.vendor << "\", \"compute_units\": " << d.compute_units
                << ", \"global_mem_bytes\": " << d.global_mem << ", \"max_alloc_bytes\": " << d.max_alloc
                << ", \"opencl_c\": \"" << d.opencl_c_version << "\", \"driver\": \"" << d.driver_version << "\"}";
    }
    std::cout << "]}\n";
    return 0;
  }
  std::size_t wname = 4, wplat = 8;
  for (const auto& d : devices) {
    wname = std::max(wname, d.device_name.size());
    wplat = std::max(wplat, d.platform_name.size());
  }
  std::cout << std::left << "  " << std::setw(4) << "#" << std::setw(6) << "type" << std::setw(wname + 2) << "name"
            << std::setw(wplat + 2) << "platform" << std::right << std::setw(4) << "CUs" << std::setw(12)
            << "global mem" << std::setw(12) << "max alloc" << "  OpenCL C / driver\n";
  for (const auto& d : devices) {
    std::cout << (d.index == chosen ? "* " : "  ") << std::left << std::setw(4) << d.index << std::setw(6) << d.type
              << std::setw(wname + 2) << d.device_name << std::setw(wplat + 2) << d.platform_name << std::right
              << std::setw(4) << d.compute_units << std::setw(12) << human_bytes(double(d.global_mem))
              << std::setw(12) << human_bytes(double(d.max_alloc)) << "  " << d.opencl_c_version << " / "
              << d.driver_version << '\n';
  }
  if (chosen >= 0)
    std::cout << "* = used by default; choose with --device INDEX|NAME|cpu|gpu or SOFTSHELL_DEVICE\n";
  else
    std::cout << "note: " << why << '\n';
  const std::string cache = ensure_pocl_cache_dir();
  if (!cache.empty()) std::cout << "PoCL kernel cache: " << cache << '\n';
  return 0;
}

}  // namespace

void add_devices_command(CLI::App& app, Action& action) {
  auto json = std::make_shared<bool>(false);
  auto* sub = app.add_subcommand("devices", "List OpenCL platforms and devices with their index");
  sub->add_flag("--json", *json, "Machine-readable output");
  sub->callback([&action, json] { action = [json] { return run_devices(*json); }; });
}

}  // namespace softshell::cli
