// Test support for the owners of the world strand (server/world/): a
// scratch SQLite world (its chunk reads optionally held at a gate), its
// Storage, an io_context on a thread of its own with the world's strand,
// and on_strand(fn), which runs fn there and waits; and RecordingClient,
// a WorldClient that records what it is told.
#pragma once

#include <gtest/gtest.h>

#include <asio.hpp>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "protocol/messages.h"
#include "server/storage/storage.h"
#include "server/world/world_client.h"
#include "tests/support/eventually.h"
#include "tests/support/gated_store.h"
#include "tests/support/scratch_dir.h"

namespace terrane::testing_support {

class RecordingClient : public WorldClient {
 public:
  void granted(std::vector<VersionPtr> versions) override {
    std::lock_guard lock(m);
    for (auto& v : versions) grants.push_back(std::move(v));
    cv.notify_all();
  }
  void horizons(std::vector<HorizonPtr> images) override {
    std::lock_guard lock(m);
    for (auto& i : images) images_.push_back(std::move(i));
    cv.notify_all();
  }
  void committed(std::uint64_t tick, std::vector<VersionPtr> changed) override {
    std::lock_guard lock(m);
    ticks.emplace_back(tick, std::move(changed));
    cv.notify_all();
  }
  void mips_changed(std::uint64_t tick, std::vector<VersionPtr> changed) override {
    std::lock_guard lock(m);
    mip_news.emplace_back(tick, std::move(changed));
    cv.notify_all();
  }
  void answer(WorldAnswer a) override {
    std::lock_guard lock(m);
    answers.push_back(std::move(a));
    cv.notify_all();
  }
  void close(CloseReason, const std::string& reason) override {
    std::lock_guard lock(m);
    closed = reason;
    cv.notify_all();
  }
  // Waits (up to a minute) until p(*this) holds, under the lock.
  template <class Pred>
  bool wait(Pred p) {
    std::unique_lock lock(m);
    return cv.wait_for(lock, std::chrono::seconds(60), [&] { return p(*this); });
  }
  // The answers of type T received, in order (under the lock).
  template <class T>
  std::vector<T> answered() const {
    std::vector<T> out;
    for (const WorldAnswer& a : answers)
      if (const T* t = std::get_if<T>(&a)) out.push_back(*t);
    return out;
  }
  // The edit ids of the edits acknowledged, in order (under the lock).
  std::vector<std::uint32_t> acked() const {
    std::vector<std::uint32_t> ids;
    for (const EditAcked& a : answered<EditAcked>()) ids.push_back(a.edit_id);
    return ids;
  }

  std::mutex m;
  std::condition_variable cv;
  std::vector<VersionPtr> grants;
  std::vector<HorizonPtr> images_;
  std::vector<std::pair<std::uint64_t, std::vector<VersionPtr>>> ticks, mip_news;
  std::vector<WorldAnswer> answers;
  std::string closed;
};

// A world, its Storage and the strand. Members public: the owners under
// test are made by the test on top, and call quiesce() before they go.
class WorldStrand {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;

  // gate: reads of its chunks wait until it opens (null: none).
  explicit WorldStrand(std::shared_ptr<StoreGate> gate = nullptr) {
    dir = scratch_dir("terrane-world-strand");
    auto store = SqliteStore::create(dir.string(), default_world_meta());
    EXPECT_TRUE(store.ok());
    std::unique_ptr<WorldStore> inner = std::move(*store);
    if (gate) inner = std::make_unique<GatedStore>(std::move(inner), gate);
    auto w = World::open(std::move(inner));
    EXPECT_TRUE(w.ok());
    world = std::move(*w);
    // Gated: loaders to spare for the chunks not waiting at the gate.
    auto s = Storage::open(*world, gate ? 3 : 1);
    EXPECT_TRUE(s.ok());
    storage = std::move(*s);
    thread = std::thread([this] { io.run(); });
  }
  ~WorldStrand() {
    quiesce();
    work.reset();
    io.stop();
    thread.join();
    storage.reset();
    world.reset();
    std::filesystem::remove_all(dir);
  }
  WorldStrand(const WorldStrand&) = delete;
  WorldStrand& operator=(const WorldStrand&) = delete;

  // Stops the storage (its loads done) and runs what it posted to the
  // strand: call before the owners on the strand go.
  void quiesce() {
    storage->stop();
    on_strand([] {});
  }
  // Runs fn on the strand and waits for it.
  void on_strand(const std::function<void()>& fn) {
    std::promise<void> done;
    asio::post(strand, [&] {
      fn();
      done.set_value();
    });
    done.get_future().wait();
  }
  // Asks pred on the strand until it holds (up to a minute).
  bool eventually_on_strand(const std::function<bool()>& pred) {
    return eventually([&] {
      bool ok = false;
      on_strand([&] { ok = pred(); });
      return ok;
    });
  }

  std::filesystem::path dir;
  std::unique_ptr<World> world;
  std::unique_ptr<Storage> storage;
  asio::io_context io;
  asio::executor_work_guard<asio::io_context::executor_type> work{asio::make_work_guard(io)};
  Strand strand{asio::make_strand(io)};
  std::thread thread;
};

}  // namespace terrane::testing_support
