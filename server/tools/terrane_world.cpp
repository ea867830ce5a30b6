// terrane-world: create, fill, inspect, convert and move Terrane worlds.
//
//   terrane-world generate --world DIR|--store URL [--server-id N] [--box x0,y0,z0,x1,y1,z1] [--seed N]
//   terrane-world import   --world DIR|--store URL [--server-id N] FILE.vxraw[.gz]
//   terrane-world export   --world DIR|--store URL --box x0,y0,z0,x1,y1,z1 FILE.vxraw[.gz]
//   terrane-world stats    --world DIR|--store URL [--box ...] [--json]
//   terrane-world check    --world DIR [--quarantine]
//   terrane-world backup   --world DIR --to DEST
//   terrane-world migrate  --world DIR --to postgresql://... [--server-id N]
//
// A world is a directory (SQLite) or a PostgreSQL database (a postgresql://
// URL; --world and --store each take either, as terrane-server's do). A
// command that writes a PostgreSQL world takes the leases of the regions it
// writes for a server id of its own (a LeaseKeeper, as a server does) and
// gives them up at the end. Messages name a database without its password.
//
// Exit status: 0 on success, 1 on a failure of the work (I/O, damaged data),
//
// The commands are in server/tools/: write_commands.cpp (generate,
// import), read_commands.cpp (export, stats, check), copy_commands.cpp
// (backup, migrate), enhance_command.cpp (enhance); world_tool.h has what
// they share.

#include <cstdio>
#include <string>

#include "server/tools/enhance_command.h"
#include "server/tools/world_tool.h"

namespace terrane::world_tool {
namespace {

constexpr const char* kUsage =
    "usage: terrane-world COMMAND (--world DIR | --store URL) [options]\n"
    "\n"
    "A world is a directory (SQLite: one server) or a PostgreSQL database shared by several\n"
    "servers (--store postgresql://[USER@]HOST:PORT/DB; server/storage/STORE_POSTGRESQL.md).\n"
    "--world and --store each take either. Commands that write a PostgreSQL world take the\n"
    "leases of the regions they write for a server id of their own (--server-id N).\n"
    "A world directory has one writer at a time: generate, import, migrate and check\n"
    "--quarantine take its lock (world.lock) and are refused, naming the holder, while a\n"
    "server serves it; check, stats, export and backup only read and may run beside one.\n"
    "\n"
    "Commands:\n"
    "  generate   create a generated world (if there is none) and pre-generate a box of it\n"
    "  import     write a VXRAW box (plain or .gz) into a world, creating an empty world if needed\n"
    "  export     write a box of a world to a VXRAW file (.gz: gzip-compressed)\n"
    "  stats      the storage results table for a box: voxels, codecs, memory\n"
    "  check      decode every stored chunk, list quarantined ones (exit 1 on any of either)\n"
    "  backup     copy a world directory, consistently, even while a server is writing to it\n"
    "             (a PostgreSQL world: pg_dump)\n"
    "  migrate    copy a world directory into a PostgreSQL database that holds no world yet\n"
    "  enhance    voxel detail enhancement of a VXRAW box (subdivision or resampling, lighting)\n"
    "\n"
    "Run 'terrane-world COMMAND --help' for a command's options.\n";

}  // namespace
}  // namespace terrane::world_tool

int main(int argc, char** argv) {
  using namespace terrane::world_tool;
  if (argc < 2) return usage_error("no command given", kUsage);
  const std::string cmd = argv[1];
  if (cmd == "--help" || cmd == "-h" || cmd == "help") return std::printf("%s", kUsage), 0;
  if (cmd == "generate") return cmd_generate(argc, argv);
  if (cmd == "import") return cmd_import(argc, argv);
  if (cmd == "export") return cmd_export(argc, argv);
  if (cmd == "stats") return cmd_stats(argc, argv);
  if (cmd == "check") return cmd_check(argc, argv);
  if (cmd == "backup") return cmd_backup(argc, argv);
  if (cmd == "migrate") return cmd_migrate(argc, argv);
  if (cmd == "enhance") return terrane::run_enhance_command(argc, argv);
  return usage_error("unknown command '" + cmd + "'", kUsage);
}
