// terrane-world enhance: voxel detail enhancement of a VXRAW file (see
// common/enhance/ENHANCE.md), optionally with snowflake-traced lighting.
//
//   terrane-world enhance --in FILE.vxraw --out FILE.vxraw --method subdivide|resample
//                         [--factor N] [--threshold T] [--probes N] [--spread S] [--seed N] [--light]
#pragma once

namespace terrane {

// argv[1] is "enhance"; options start at argv[2]. Returns the exit status:
// 0 success, 1 a file could not be read or written, 2 bad usage (the message
// names the option and value). Progress for long runs goes to stderr, the
// summary to stdout.
int run_enhance_command(int argc, char** argv);

}  // namespace terrane
