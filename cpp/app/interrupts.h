#pragma once
// Ctrl-C (SIGINT) and SIGTERM for calibproj-native: an interruption runs the cleanup of
// the output being written (its staging folder goes, the previous output stays) and
// exits with status 130, as the Python commands do on Ctrl-C.
//
// The signals are blocked in the thread that creates Interrupts, and so in every thread
// started afterwards, and taken by a thread of its own (sigwait): the cleanup runs as
// ordinary code, not in a signal handler. The writes and renames of an output happen
// inside a Hold(): an interruption waits for such a section to end and exits before
// the next one starts, so it never sees half a rename.

#include <signal.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "calibproj/formats/output_folder.h"

namespace calibproj::app {

class Interrupts : public formats::InterruptionSections {
 public:
  // `prefix` starts the message an interruption prints ("calibproj-native calibrate").
  explicit Interrupts(std::string prefix);
  ~Interrupts();
  Interrupts(const Interrupts&) = delete;
  Interrupts& operator=(const Interrupts&) = delete;

  // A section that an interruption waits for.
  std::unique_lock<std::mutex> Hold() override;

  // What an interruption does before it exits (an empty function: nothing); set within
  // a section, so that it always matches what is on disk.
  void SetCleanup(const std::unique_lock<std::mutex>& held, std::function<void()> cleanup) override;

  // What an interruption stops before the cleanup (a capture's player and cameras, which
  // it waits for, so that their recordings are complete); set outside any section.
  void SetStopper(std::function<void()> stopper);

  static constexpr int kExitStatus = 130;  // 128 + SIGINT, as shells report it

 private:
  void WaitForSignals();

  std::string prefix_;
  sigset_t signals_;
  sigset_t previous_mask_;
  std::mutex mutex_;
  std::function<void()> cleanup_;
  std::mutex stopper_mutex_;
  std::function<void()> stopper_;
  std::atomic<bool> stopping_{false};
  std::thread waiter_;
};

}  // namespace calibproj::app
