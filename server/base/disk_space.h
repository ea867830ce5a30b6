// Free space on the file system that holds a path: for the start's check
// (--min-free-mb, Server::open_world) and the terrane_disk_free_bytes
// gauge. A leaf utility; any thread.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace terrane {

// Bytes an unprivileged writer may still use on path's file system
// (statvfs: f_bavail * f_frsize); nullopt if path cannot be examined.
std::optional<std::uint64_t> free_bytes(const std::string& path);

}  // namespace terrane
