// The server's threads by role. Each is named (at most 15 characters
// shown), so `top -H`, `perf report --sort comm` and a debugger tell the
// owners apart, and, unless turned off (--no-thread-priorities), runs at a
// niceness by how directly a delay there delays what clients wait for:
//
// | thread         | niceness | why                                                  |
// |----------------|----------|------------------------------------------------------|
// | terrane-world  | -5       | ticks: every acknowledgement and update waits on one |
// | terrane-writer | -5       | each tick's group commit: acks and updates follow it |
// | terrane-io     | 0        | sessions and replicators: live traffic and streaming |
// | terrane-loader | +5       | loads and generation: streaming, no deadline         |
//
// Relative to the process's niceness. On a machine with cores to spare
// nothing changes; on a busy one (or with clients on the same machine) the
// threads every edit passes through are not starved by streaming. Raising
// a thread needs CAP_SYS_NICE or RLIMIT_NICE: without them the world and
// the writer run at the process's niceness (best effort, reported).
#pragma once

namespace terrane {

enum class ThreadRole { kWorld, kWriter, kIo, kLoader };

// Names the calling thread after its role and, when prioritise, sets its
// niceness. False when the niceness could not be set (the name always is).
bool enter_thread_role(ThreadRole role, bool prioritise);

// The niceness a role runs at, relative to the process's.
int thread_role_niceness(ThreadRole role);

}  // namespace terrane
