// Video files through libavcodec/libavformat: H.264 in MP4 and VP9 in WebM, the
// two codecs every current browser plays, and an animated GIF loop for slides
// and pages that cannot play video. Frames are encoded as they arrive, so
// memory stays flat however long the run is. No FFmpeg types appear here.
#pragma once

#include <memory>
#include <string>

#include "render/image.h"
#include "render/status.h"

namespace collido::render {

enum class VideoCodec {
  kH264,  // MP4, yuv420p
  kVP9,   // WebM, yuv420p
  kGif,   // GIF, 256 colours (3-3-2, dithered), loops forever; usually scaled down
};

struct VideoOptions {
  VideoCodec codec = VideoCodec::kH264;
  int width = 1280;  // pixels of the output; even for H.264 and VP9 (yuv420p halves chroma)
  int height = 720;  // pixels of the output; even for H.264 and VP9
  // Size of the images given to add_frame when it differs from the output
  // (they are scaled); 0 = the same as width x height.
  int source_width = 0, source_height = 0;
  int fps = 30;         // frames per second of the output, divided by fps_divisor:
  int fps_divisor = 1;  // a GIF keeping every few frames of a 25 fps clip plays 25/2 a second
  // Constant quality: x264 CRF (0..51, 18 looks lossless, 23 default) or VP9 CRF
  // (0..63). Negative picks the codec's default for this renderer.
  int crf = -1;
  // Encoder threads; 0 lets the encoder choose from the core count.
  int threads = 0;
};

// File name extension that goes with a codec ("mp4", "webm" or "gif").
const char* video_extension(VideoCodec codec);

class VideoWriter {
 public:
  // Opens path (written to a temporary name, renamed on finish()). nullptr and
  // *status on failure, e.g. when libavcodec was built without the encoder.
  static std::unique_ptr<VideoWriter> open(const std::string& path, const VideoOptions& options,
                                           Status* status);
  ~VideoWriter();  // abandons the temporary file unless finish() succeeded

  // Encodes one frame; image must have the size given in the options.
  Status add_frame(const Image& image);
  // Drains the encoder, writes the trailer (MP4: index moved to the front for
  // progressive playback) and renames the file into place.
  Status finish();

  int frames_written() const;
  // Name of the libavcodec encoder in use, e.g. "libx264" or "libvpx-vp9".
  std::string encoder_name() const;

 private:
  struct Impl;
  explicit VideoWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// What a video file contains, found by decoding it completely.
struct VideoInfo {
  std::string container;  // libavformat's name, e.g. "mov,mp4,m4a,3gp,3g2,mj2"
  std::string codec;      // e.g. "h264", "vp9"
  std::string pixel_format;
  int width = 0, height = 0;
  int frames = 0;               // frames decoded
  double duration_s = 0;        // container duration, seconds
  double fps = 0;               // average frame rate the stream declares
  bool index_at_front = false;  // MP4 only: "moov" before "mdat" (+faststart)
};

// Opens and decodes a whole video; used by tests and to check outputs.
Status probe_video(const std::string& path, VideoInfo* info);

// Decodes frame `index` (0-based, in display order) to RGB, converting with
// the colour matrix the stream declares; for thumbnails and colour checks.
Status read_video_frame(const std::string& path, int index, Image* image);

}  // namespace collido::render
