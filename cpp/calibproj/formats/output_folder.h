#pragma once
// Outputs written as one transaction: the one implementation both tools use (the Python
// package binds it as formats.OutputFolder/OutputFile), with one set of file names, one
// lock and one set of messages, so that any two runs on the same output exclude each other.
//
// OutputFolder(path):
// 1. Open(), before any long work, checks that the folder can be written and says so in
//    one line naming the path when it cannot (an existing file, a parent folder that is
//    not writable, a full disk, results already there without force, a folder of other
//    files); it takes the lock (flock on `.<name>.lock` beside the folder: a second run
//    fails at once) and creates the staging folder `.<name>.tmp-XXXXXX` beside it;
// 2. Write() writes into the staging folder;
// 3. Commit() moves the staging folder into place (the previous folder aside, the new
//    one in, the previous one deleted): force replaces the whole previous folder.
// Abort() (also on destruction, and on an interruption) deletes the staging folder and
// leaves the previous folder as it was. A run killed outright leaves at most a hidden
// staging folder, which the next run on the same path deletes.
//
// OutputFile(path) does the checks and the locking for a command that writes single
// files (detect), each of them written atomically.
//
// An interruption handler (calibproj-native's) is given as InterruptionSections: the
// writes and renames then happen inside its sections, and its cleanup always matches
// what is on disk. Without one (Python, where a signal only sets a flag that the
// interpreter reads after the call), each call is a whole step already.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

// What an interruption handler offers an output: sections it waits for before it acts,
// and the cleanup it runs then (set inside a section).
class InterruptionSections {
 public:
  virtual std::unique_lock<std::mutex> Hold() = 0;
  virtual void SetCleanup(const std::unique_lock<std::mutex>& held, std::function<void()> cleanup) = 0;

 protected:
  ~InterruptionSections() = default;
};

// An output that cannot be written, named in the message: exit status 2.
class OutputError : public InputError {
 public:
  using InputError::InputError;
};

// Another run (native or Python) holds the lock of the same output: exit status 1.
class OutputBusyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Below this much free space on the disk of the output, a run is refused before it
// starts (the results of a calibration take a few megabytes).
constexpr std::uintmax_t kMinFreeBytes = 8 * 1024 * 1024;

// `text` as Python's pathlib spells it ("out/" and "./out" are "out"), so that the
// messages name a path as the Python commands do.
std::filesystem::path PathlibPath(const std::string& text);

// An exclusive flock on a lock file, taken without waiting (Python's fcntl.flock on the
// same file excludes it, and the other way round).
class OutputLock {
 public:
  OutputLock() = default;
  ~OutputLock() { Release(); }
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

  // OutputBusyError when another run holds it; OutputError naming `target` when the
  // lock file cannot be created.
  void Acquire(const std::filesystem::path& lock_file, const std::filesystem::path& target);
  // Deletes the lock file, then lets go of it.
  void Release() noexcept;

 private:
  std::filesystem::path path_;
  int fd_ = -1;
};

// The sections of an optional interruption handler.
class Sections {
 public:
  explicit Sections(InterruptionSections* interrupts) : interrupts_(interrupts) {}
  // A section of the handler, or nothing to hold without one.
  std::unique_lock<std::mutex> Hold() const {
    return interrupts_ != nullptr ? interrupts_->Hold() : std::unique_lock<std::mutex>();
  }
  void SetCleanup(const std::unique_lock<std::mutex>& held, std::function<void()> cleanup) const {
    if (interrupts_ != nullptr) interrupts_->SetCleanup(held, std::move(cleanup));
  }

 private:
  InterruptionSections* interrupts_;
};

class OutputFolder {
 public:
  // signature: files of which at least one marks a folder this command wrote; a
  // non-empty folder holding none of them is refused, with force or without (force
  // never deletes a folder of other files).
  // min_free_bytes: the free space below which Open() refuses (kMinFreeBytes unless a
  // caller knows its output to be larger).
  OutputFolder(const std::string& path, bool force, std::vector<std::string> signature,
               InterruptionSections* interrupts = nullptr, std::uintmax_t min_free_bytes = kMinFreeBytes);
  ~OutputFolder() { Abort(); }
  OutputFolder(const OutputFolder&) = delete;
  OutputFolder& operator=(const OutputFolder&) = delete;

  // Checks, locks, and creates the staging folder.
  void Open();
  // Calls write(staging); a filesystem error in it is an OutputError naming the folder.
  void Write(const std::function<void(const std::filesystem::path& staging)>& write);
  // Moves the staging folder into place and releases the lock.
  void Commit();
  // Deletes the staging folder and releases the lock; the previous folder stays.
  void Abort() noexcept;

  const std::filesystem::path& path() const { return path_; }
  // The staging folder while one is open (empty before Open and after Commit or Abort).
  const std::filesystem::path& staging() const { return staging_; }

 private:
  void Recover(const std::filesystem::path& parent);
  void CheckExisting() const;
  void CreateStaging(const std::filesystem::path& parent);
  void MoveIntoPlace();
  // Abort() for a caller that holds the interrupts (and for the interruption itself).
  void Discard() noexcept;

  std::filesystem::path path_;
  bool force_;
  std::vector<std::string> signature_;
  Sections sections_;
  std::uintmax_t min_free_bytes_;
  OutputLock lock_;
  std::vector<std::filesystem::path> created_;  // folders made for it, deepest first
  std::filesystem::path staging_;  // empty when there is none
};

class OutputFile {
 public:
  // force: an existing file may be replaced; inputs: files of the run that the output
  // must never replace, force or not.
  OutputFile(const std::string& path, bool force = false, std::vector<std::string> inputs = {},
             InterruptionSections* interrupts = nullptr, std::uintmax_t min_free_bytes = kMinFreeBytes);
  ~OutputFile() { Close(); }
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  // Checks that the file can be written (not a folder, not an input, not existing
  // unless forced, its folder writable, the disk not full) and takes its lock.
  void Open();
  // Calls write(path); a filesystem error in it is an OutputError naming the file.
  void Write(const std::function<void(const std::filesystem::path& path)>& write);
  // Releases the lock.
  void Close() noexcept;

  const std::filesystem::path& path() const { return path_; }

 private:
  // Releases the lock and removes the folders made for the file if it was not written.
  void Release() noexcept;

  std::filesystem::path path_;
  bool force_;
  std::vector<std::string> inputs_;
  Sections sections_;
  std::uintmax_t min_free_bytes_;
  OutputLock lock_;
  std::vector<std::filesystem::path> created_;  // folders made for it, deepest first
};

}  // namespace calibproj::formats
