#include "interrupts.h"

#include <pthread.h>
#include <unistd.h>

#include <cstdlib>
#include <stdexcept>

namespace calibproj::app {

Interrupts::Interrupts(std::string prefix) : prefix_(std::move(prefix)) {
  sigemptyset(&signals_);
  sigaddset(&signals_, SIGINT);
  sigaddset(&signals_, SIGTERM);
  if (pthread_sigmask(SIG_BLOCK, &signals_, &previous_mask_) != 0) {
    throw std::runtime_error("cannot block SIGINT and SIGTERM");
  }
  waiter_ = std::thread([this] { WaitForSignals(); });
}

Interrupts::~Interrupts() {
  // The waiter takes this signal as any other and sees that it is to stop.
  stopping_ = true;
  pthread_kill(waiter_.native_handle(), SIGTERM);
  waiter_.join();
  pthread_sigmask(SIG_SETMASK, &previous_mask_, nullptr);
}

std::unique_lock<std::mutex> Interrupts::Hold() { return std::unique_lock<std::mutex>(mutex_); }

void Interrupts::SetCleanup(const std::unique_lock<std::mutex>& held, std::function<void()> cleanup) {
  if (held.mutex() != &mutex_ || !held.owns_lock()) throw std::logic_error("SetCleanup outside a Hold()");
  cleanup_ = std::move(cleanup);
}

void Interrupts::SetStopper(std::function<void()> stopper) {
  const std::lock_guard<std::mutex> held(stopper_mutex_);
  stopper_ = std::move(stopper);
}

void Interrupts::WaitForSignals() {
  for (;;) {
    int number = 0;
    if (sigwait(&signals_, &number) != 0) continue;
    if (stopping_) return;
    {
      const std::lock_guard<std::mutex> held(stopper_mutex_);
      if (stopper_) stopper_();
    }
    // Held until the exit: no section of the run starts after the cleanup.
    const std::lock_guard<std::mutex> held(mutex_);
    if (cleanup_) cleanup_();
    const std::string line = prefix_ + ": interrupted\n";
    [[maybe_unused]] const auto written = write(STDERR_FILENO, line.data(), line.size());
    std::_Exit(kExitStatus);
  }
}

}  // namespace calibproj::app
