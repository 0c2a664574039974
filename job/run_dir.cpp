#include "job/run_dir.h"

#include <algorithm>
#include <filesystem>

#include "common/atomic_file.h"

namespace collido::job {

namespace fs = std::filesystem;

namespace {

// Removes the temporary files a killed writer left under `dir`.
void remove_temporaries(const fs::path& dir) {
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file(ec) && is_temp_name(it->path().filename().string()))
      fs::remove(it->path(), ec);
}

}  // namespace

bool holds_a_run(const std::string& dir_name) {
  const fs::path dir(dir_name);
  std::error_code ec;
  for (const char* marker : {"job.json", "result.json", "scene.json", "stats.csv.partial"})
    if (fs::exists(dir / marker, ec)) return true;
  return fs::is_directory(dir / "frames", ec);
}

Status claim_run_dir(const std::string& dir_name, DirPolicy policy) {
  if (dir_name.empty()) return invalid_argument("out: the run directory is empty");
  const fs::path dir(dir_name);
  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    return invalid_argument(dir_name + ": exists and is not a directory");
  if (fs::is_directory(dir, ec)) {
    remove_temporaries(dir);
    const bool empty = fs::is_empty(dir, ec);
    if (ec) return io_error(dir_name + ": cannot read it: " + ec.message());
    if (policy == DirPolicy::kResume) {
      if (!holds_a_run(dir.string())) return not_found(dir_name + ": holds no run to resume");
    } else if (!empty) {
      if (policy == DirPolicy::kRefuse)
        return invalid_argument(dir_name +
                                ": already holds files; choose another directory, replace the "
                                "run (--force) or continue it (--resume)");
      if (!holds_a_run(dir.string()))
        return invalid_argument(dir_name + ": holds files but no run; not replacing it");
      // Every entry goes, or the run stops: an old file left behind would be
      // listed, or rendered, as the new run's.
      for (const auto& entry : fs::directory_iterator(dir, ec)) {
        std::error_code rm;
        fs::remove_all(entry.path(), rm);
        if (rm) return io_error(entry.path().string() + ": cannot remove it: " + rm.message());
      }
      if (ec) return io_error(dir_name + ": cannot empty it: " + ec.message());
    }
  } else if (policy == DirPolicy::kResume) {
    return not_found(dir_name + ": no such run directory");
  }
  fs::create_directories(dir / "frames", ec);
  if (ec) return io_error(dir_name + ": cannot create: " + ec.message());
  return Status::ok();
}

std::string mime_type(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  static const std::pair<const char*, const char*> kTypes[] = {
      {".mp4", "video/mp4"},        {".webm", "video/webm"},
      {".gif", "image/gif"},        {".png", "image/png"},
      {".json", "application/json"}, {".csv", "text/csv"},
      {".stl", "model/stl"},        {".vtp", "application/xml"},
      {".pvd", "application/xml"},  {".snap", "application/octet-stream"},
      {".bin", "application/octet-stream"}};
  for (const auto& [e, type] : kTypes)
    if (ext == e) return type;
  return "application/octet-stream";
}

std::vector<Artifact> list_artifacts(const RunPaths& paths, uint64_t* frame_files) {
  std::vector<Artifact> out;
  std::error_code ec;
  auto add_file = [&](const std::string& rel, const std::string& role) {
    const fs::path p = fs::path(paths.dir) / rel;
    if (!fs::is_regular_file(p, ec)) return;
    out.push_back({rel, uint64_t(fs::file_size(p, ec)), mime_type(rel), role, 1});
  };
  // A folder of frames is one entry: its total size and how many files.
  auto add_folder = [&](const std::string& rel, const std::string& ext, const std::string& role) {
    const fs::path p = fs::path(paths.dir) / rel;
    if (!fs::is_directory(p, ec)) return uint64_t(0);
    Artifact a{rel + "/", 0, mime_type("x" + ext), role, 0};
    for (const auto& e : fs::directory_iterator(p, ec))
      if (e.is_regular_file(ec) && e.path().extension() == ext &&
          !is_temp_name(e.path().filename().string()))
        a.bytes += uint64_t(e.file_size(ec)), ++a.count;
    if (a.count) out.push_back(a);
    return a.count;
  };
  add_file("render/video.mp4", "video");
  add_file("render/video.webm", "video");
  add_file("render/loop.gif", "gif");
  add_file("render/poster.png", "poster");
  add_file("stats.csv", "stats");
  add_file("scene.json", "scene");
  add_file("wall.stl", "wall");
  add_file("frames.pvd", "paraview");
  const uint64_t snaps = add_folder("frames", ".snap", "snapshots");
  if (frame_files) *frame_files = snaps;
  add_folder("render/frames", ".png", "frame_images");
  add_folder("vtp", ".vtp", "paraview");
  return out;
}

}  // namespace collido::job
