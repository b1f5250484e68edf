// Version of the native core; the Python package reports it so a stale build is visible.
#pragma once
namespace sim_core {
inline constexpr const char* kVersion = "0.1.0";
}
