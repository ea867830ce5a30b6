// The server's threads by role. Each is named (at most 15 characters
// shown), so `top -H`, `perf report --sort comm` and a debugger tell the
// owners apart, and, unless turned off (--no-thread-priorities), runs at a
// niceness relative to the process's:
//
// | thread         | niceness | what it runs                                          |
// |----------------|----------|-------------------------------------------------------|
// | terrane-world  | 0        | ticks, and streaming's requests between them          |
// | terrane-writer | 0        | each tick's group commit, then coarse images          |
// | terrane-io     | 0        | sessions and replicators: live traffic and streaming  |
// | terrane-loader | +5       | loads and generation: streaming's, without a deadline |
//
// On a machine with cores to spare nothing changes; on a busy one the
// loaders yield to the threads that edits pass through. The world and the
// writer are not raised above the rest: the world strand also answers
// streaming's requests, and at 1,000 clients with the bots on the same
// machine a world thread at -5 (with the writer) took the cores from the
// clients' side in bursts until every queue grew (docs/results.md, "Replication scale").
// A role at a niceness above the process's would need CAP_SYS_NICE: set
// best effort, reported.
#pragma once

namespace terrane {

enum class ThreadRole { kWorld, kWriter, kIo, kLoader };

// Names the calling thread after its role and, when prioritise, sets its
// niceness. False when the niceness could not be set (the name always is).
bool enter_thread_role(ThreadRole role, bool prioritise);

// The niceness a role runs at, relative to the process's.
int thread_role_niceness(ThreadRole role);

}  // namespace terrane
