#include "calibproj/formats/output_folder.h"

#include <fcntl.h>
#include <linux/fs.h>
#include <sys/ioctl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <sstream>
#include <system_error>

namespace calibproj::formats {

namespace fs = std::filesystem;

namespace {

// Whether the file or folder carries the immutable or append-only flag (chattr +i, +a):
// it cannot then be renamed or replaced, which the final move of a run would find only
// after all the work.
bool Unreplaceable(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return false;
  int flags = 0;
  const bool got = ::ioctl(fd, FS_IOC_GETFLAGS, &flags) == 0;
  ::close(fd);
  return got && (flags & (FS_IMMUTABLE_FL | FS_APPEND_FL)) != 0;
}

void RequireReplaceable(const fs::path& path) {
  if (Unreplaceable(path)) {
    throw OutputError(path.string() + ": cannot be replaced (it is immutable or append-only; chattr -i -a lifts that)");
  }
}

constexpr const char* kProbePrefix = ".calibproj-probe-";
constexpr size_t kProbeBytes = 64 * 1024;
constexpr const char* kPrevious = "previous";  // the previous folder, inside the folder it is moved aside to

std::string Described(int error) { return std::system_category().message(error); }

fs::filesystem_error ErrnoError(const std::string& what, const fs::path& path) {
  return fs::filesystem_error(what, path, std::error_code(errno, std::system_category()));
}

// Python's Path.parent: "." for a name without a folder.
fs::path ParentOf(const fs::path& path) { return path.has_parent_path() ? path.parent_path() : fs::path("."); }

// The folders on the way to `folder` that do not exist yet, deepest first: those a run
// creates for its output, and removes again when it ends without writing into them.
std::vector<fs::path> MissingFolders(fs::path folder) {
  std::vector<fs::path> missing;
  std::error_code error;
  while (!folder.empty() && !fs::exists(folder, error) && folder != folder.parent_path()) {
    missing.push_back(folder);
    folder = folder.parent_path();
  }
  return missing;
}

// Removes the folders that are still empty, deepest first (a folder that holds the
// output, or anything else, stays, and so do those above it).
void RemoveEmptyFolders(const std::vector<fs::path>& folders) noexcept {
  for (const fs::path& folder : folders) {
    std::error_code error;
    if (!fs::is_directory(folder, error) || !fs::is_empty(folder, error) || error) return;
    if (!fs::remove(folder, error)) return;
  }
}

// The file mode bits a plain mkdir() or open() would clear.
mode_t CurrentUmask() {
  const mode_t mask = umask(0);
  umask(mask);
  return mask;
}

// Creates the parent folder if needed; OutputError when it cannot be written or the
// disk is full.
fs::path CheckParent(const fs::path& target, std::uintmax_t min_free_bytes) {
  const fs::path parent = ParentOf(target);
  const std::string prefix = target.string() + ": ";
  std::error_code error;
  if (fs::exists(parent, error) && !fs::is_directory(parent, error)) {
    throw OutputError(prefix + parent.string() + " is not a folder");
  }
  fs::create_directories(parent, error);
  if (error) throw OutputError(prefix + "cannot create " + parent.string() + " (" + error.message() + ")");
  if (!fs::is_directory(parent)) throw OutputError(prefix + parent.string() + " is not a folder");
  if (access(parent.c_str(), W_OK | X_OK) != 0) {
    throw OutputError(prefix + "cannot write in " + parent.string() + " (permission denied)");
  }
  struct statvfs stats {};
  if (statvfs(parent.c_str(), &stats) != 0) {
    throw OutputError(prefix + "cannot inspect " + parent.string() + " (" + Described(errno) + ")");
  }
  if (stats.f_flag & ST_RDONLY) {
    throw OutputError(prefix + "cannot write in " + parent.string() + " (read-only file system)");
  }
  const std::uintmax_t free = static_cast<std::uintmax_t>(stats.f_bavail) * stats.f_frsize;
  if (free < min_free_bytes) {
    char line[160];
    std::snprintf(line, sizeof(line), "the disk is full (%.1f MiB free in %s, %.0f MiB needed to start)",
                  free / 1048576.0, parent.c_str(), min_free_bytes / 1048576.0);
    throw OutputError(prefix + line);
  }
  return parent;
}

// CheckParent, the folders it made (`created`) removed again when it fails.
fs::path CheckParentMade(const fs::path& target, const std::vector<fs::path>& created, std::uintmax_t min_free_bytes) {
  try {
    return CheckParent(target, min_free_bytes);
  } catch (...) {
    RemoveEmptyFolders(created);
    throw;
  }
}

// Writes, syncs and deletes a small file in `folder`: OutputError naming `target` if
// that fails (a full disk shows here even when statvfs does not tell).
void Probe(const fs::path& folder, const fs::path& target) {
  std::string name = (folder / (std::string(kProbePrefix) + "XXXXXX")).string();
  const int fd = mkostemp(name.data(), O_CLOEXEC);
  if (fd < 0) throw OutputError(target.string() + ": cannot write (" + Described(errno) + ")");
  unlink(name.c_str());
  const bool written = WriteFully(fd, std::string(kProbeBytes, '\0')) && fsync(fd) == 0;
  const int error = errno;
  close(fd);
  if (!written) throw OutputError(target.string() + ": cannot write (" + Described(error) + ")");
}

// A new folder `<parent>/<prefix>XXXXXX`, with the permissions mkdir() would give.
fs::path MakeUniqueFolder(const fs::path& parent, const std::string& prefix) {
  std::string name = (parent / (prefix + "XXXXXX")).string();
  if (mkdtemp(name.data()) == nullptr) throw ErrnoError("cannot create a folder", name);
  fs::permissions(name, static_cast<fs::perms>(0777 & ~CurrentUmask()));  // mkdtemp makes 0700
  return name;
}

// The entries of `parent` whose names start with `prefix`, in name order.
std::vector<fs::path> EntriesStartingWith(const fs::path& parent, const std::string& prefix) {
  std::vector<fs::path> found;
  for (const auto& entry : fs::directory_iterator(parent)) {
    if (entry.path().filename().string().rfind(prefix, 0) == 0) found.push_back(entry.path());
  }
  std::sort(found.begin(), found.end());
  return found;
}

// Makes the renames in `folder` durable.
void SyncFolder(const fs::path& folder) {
  const int fd = open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  fsync(fd);
  close(fd);
}

std::string Joined(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : ", ") + item;
  return out;
}

// The path a symbolic link leads to, absolute, also when it leads nowhere yet (as
// Python's Path.resolve()): the output is written there, not over the link.
fs::path Resolved(const fs::path& link) {
  constexpr int kMaxLinks = 40;  // as the kernel's ELOOP
  fs::path path = fs::absolute(link);
  for (int followed = 0; followed < kMaxLinks && fs::is_symlink(path); ++followed) {
    const fs::path target = fs::read_symlink(path);
    path = target.is_absolute() ? target : path.parent_path() / target;
  }
  return fs::weakly_canonical(path);
}

// `.<name>.lock` beside the target, spelled as Python spells it (no "./" in front).
fs::path LockFileOf(const fs::path& target) {
  const std::string name = "." + target.filename().string() + ".lock";
  return target.has_parent_path() ? target.parent_path() / name : fs::path(name);
}

}  // namespace

fs::path PathlibPath(const std::string& text) {
  const bool absolute = !text.empty() && text[0] == '/';
  std::string spelled = absolute ? "/" : "";
  std::istringstream parts(text);
  std::string part;
  bool first = true;
  while (std::getline(parts, part, '/')) {
    if (part.empty() || part == ".") continue;
    spelled += (first ? "" : "/") + part;
    first = false;
  }
  return spelled.empty() ? fs::path(".") : fs::path(spelled);
}

// -- the lock ------------------------------------------------------------------------------

void OutputLock::Acquire(const fs::path& lock_file, const fs::path& target) {
  for (;;) {
    const int fd = open(lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) {
      throw OutputError(target.string() + ": cannot write in " + ParentOf(target).string() + " (" +
                        Described(errno) + ")");
    }
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      close(fd);
      if (error == EWOULDBLOCK || error == EAGAIN || error == EACCES) {
        throw OutputBusyError(target.string() + ": another calibproj run is writing it (lock held on " +
                              lock_file.string() + "); wait for it to end or choose another output");
      }
      throw OutputError(target.string() + ": cannot lock " + lock_file.string() + " (" + Described(error) + ")");
    }
    // The run that held the lock may have deleted the file just before: then this lock
    // is on a file nobody else sees, and is taken again.
    struct stat held {}, named {};
    if (fstat(fd, &held) == 0 && stat(lock_file.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
        held.st_ino == named.st_ino) {
      path_ = lock_file;
      fd_ = fd;
      return;
    }
    close(fd);
  }
}

void OutputLock::Release() noexcept {
  if (fd_ < 0) return;
  unlink(path_.c_str());
  close(fd_);
  fd_ = -1;
}

// -- the folder ----------------------------------------------------------------------------

OutputFolder::OutputFolder(const std::string& path, bool force, std::vector<std::string> signature,
                           InterruptionSections* interrupts, std::uintmax_t min_free_bytes)
    : path_(PathlibPath(path)),
      force_(force),
      signature_(std::move(signature)),
      sections_(interrupts),
      min_free_bytes_(min_free_bytes) {}

void OutputFolder::Open() {
  const auto held = sections_.Hold();
  if (fs::is_symlink(path_)) path_ = Resolved(path_);
  if (fs::exists(path_) && !fs::is_directory(path_)) throw OutputError(path_.string() + ": exists and is not a folder");
  created_ = MissingFolders(ParentOf(path_));
  const fs::path parent = CheckParentMade(path_, created_, min_free_bytes_);
  lock_.Acquire(LockFileOf(path_), path_);
  sections_.SetCleanup(held, [this] { Discard(); });
  try {
    Recover(parent);
    CheckExisting();
    CreateStaging(parent);
  } catch (const fs::filesystem_error& error) {
    Discard();
    sections_.SetCleanup(held, {});
    throw OutputError(path_.string() + ": cannot write in " + parent.string() + " (" + error.code().message() + ")");
  } catch (...) {
    Discard();
    sections_.SetCleanup(held, {});
    throw;
  }
}

// Tidies what a run killed outright left (the lock is ours): its staging folders go; a
// previous folder moved aside but never replaced goes back in place.
void OutputFolder::Recover(const fs::path& parent) {
  const std::string name = path_.filename().string();
  for (const auto& stale : EntriesStartingWith(parent, "." + name + ".tmp-")) {
    std::error_code ignored;
    fs::remove_all(stale, ignored);
  }
  for (const auto& aside : EntriesStartingWith(parent, "." + name + ".old-")) {
    if (!fs::exists(path_) && fs::is_directory(aside / kPrevious)) fs::rename(aside / kPrevious, path_);
    std::error_code ignored;
    fs::remove_all(aside, ignored);
  }
}

void OutputFolder::CheckExisting() const {
  if (!fs::is_directory(path_)) return;
  std::vector<std::string> content;
  for (const auto& entry : fs::directory_iterator(path_)) content.push_back(entry.path().filename().string());
  if (content.empty()) return RequireReplaceable(path_);
  std::sort(content.begin(), content.end());
  std::vector<std::string> found;
  for (const auto& name : signature_) {
    if (fs::exists(path_ / name)) found.push_back(name);
  }
  if (!signature_.empty() && found.empty()) {
    const std::vector<std::string> shown(content.begin(), content.begin() + std::min<size_t>(content.size(), 4));
    throw OutputError(path_.string() + ": is not empty (" + Joined(shown) + (content.size() > 4 ? ", ..." : "") +
                      ") and holds no output of this command; choose another folder");
  }
  if (force_) return RequireReplaceable(path_);
  if (signature_.empty()) throw OutputError(path_.string() + ": already exists; use --force to replace it");
  throw OutputError(path_.string() + ": already holds results (" + Joined(found) + "); use --force to overwrite them");
}

void OutputFolder::CreateStaging(const fs::path& parent) {
  staging_ = MakeUniqueFolder(parent, "." + path_.filename().string() + ".tmp-");
  Probe(staging_, path_);
}

void OutputFolder::Write(const std::function<void(const fs::path& staging)>& write) {
  const auto held = sections_.Hold();
  if (staging_.empty()) throw std::logic_error("OutputFolder::Write before Open");
  try {
    write(staging_);
  } catch (const fs::filesystem_error& error) {
    throw OutputError(path_.string() + ": cannot write the output (" + error.code().message() + ")");
  }
}

void OutputFolder::Commit() {
  const auto held = sections_.Hold();
  if (staging_.empty()) throw std::logic_error("OutputFolder::Commit before Open");
  try {
    MoveIntoPlace();
  } catch (const fs::filesystem_error& error) {
    Discard();
    sections_.SetCleanup(held, {});
    throw OutputError(path_.string() + ": cannot move the output into place (" + error.code().message() + ")");
  }
  Discard();
  sections_.SetCleanup(held, {});
}

// Two renames (the previous folder aside, the staging folder in), then the previous
// folder deleted; a failed second rename puts the previous folder back.
void OutputFolder::MoveIntoPlace() {
  const fs::path parent = ParentOf(path_);
  fs::path aside;
  if (fs::exists(path_)) {
    aside = MakeUniqueFolder(parent, "." + path_.filename().string() + ".old-");
    fs::rename(path_, aside / kPrevious);
  }
  std::error_code error;
  fs::rename(staging_, path_, error);
  if (error) {
    if (!aside.empty()) {
      fs::rename(aside / kPrevious, path_);
      fs::remove_all(aside, error);
    }
    throw fs::filesystem_error("cannot rename", staging_, path_, error);
  }
  staging_.clear();
  SyncFolder(parent);
  if (!aside.empty()) fs::remove_all(aside, error);
}

void OutputFolder::Abort() noexcept {
  const auto held = sections_.Hold();
  Discard();
  sections_.SetCleanup(held, {});
}

void OutputFolder::Discard() noexcept {
  if (!staging_.empty()) {
    std::error_code ignored;
    fs::remove_all(staging_, ignored);
    staging_.clear();
  }
  lock_.Release();
  RemoveEmptyFolders(created_);
}

// -- a single file ---------------------------------------------------------------------------

OutputFile::OutputFile(const std::string& path, bool force, std::vector<std::string> inputs,
                       InterruptionSections* interrupts, std::uintmax_t min_free_bytes)
    : path_(PathlibPath(path)),
      force_(force),
      inputs_(std::move(inputs)),
      sections_(interrupts),
      min_free_bytes_(min_free_bytes) {}

void OutputFile::Open() {
  const auto held = sections_.Hold();
  if (fs::is_directory(path_)) throw OutputError(path_.string() + ": is a folder; give the path of a file");
  std::error_code error;
  if (fs::exists(path_, error)) {
    for (const std::string& input : inputs_) {
      if (fs::equivalent(path_, input, error)) {
        throw OutputError(path_.string() + ": is an input of this run; write the output elsewhere");
      }
    }
    if (!force_) throw OutputError(path_.string() + ": exists (use --force to replace it)");
    RequireReplaceable(path_);
  }
  created_ = MissingFolders(ParentOf(path_));
  const fs::path parent = CheckParentMade(path_, created_, min_free_bytes_);
  lock_.Acquire(LockFileOf(path_), path_);
  sections_.SetCleanup(held, [this] { Release(); });
  try {
    Probe(parent, path_);
  } catch (...) {
    Release();
    sections_.SetCleanup(held, {});
    throw;
  }
}

void OutputFile::Write(const std::function<void(const fs::path& path)>& write) {
  const auto held = sections_.Hold();
  try {
    write(path_);
  } catch (const fs::filesystem_error& error) {
    throw OutputError(path_.string() + ": cannot write (" + error.code().message() + ")");
  }
}

void OutputFile::Close() noexcept {
  const auto held = sections_.Hold();
  Release();
  sections_.SetCleanup(held, {});
}

void OutputFile::Release() noexcept {
  lock_.Release();
  RemoveEmptyFolders(created_);
}

}  // namespace calibproj::formats
