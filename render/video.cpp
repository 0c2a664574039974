// Video encoding and probing with libavcodec/libavformat/libswscale (FFmpeg 5.1
// on Debian 12). Browsers need yuv420p, an even frame size, H.264 in MP4 with
// the index ("moov") in front for progressive playback, or VP9 in WebM.
extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <string>

#include "common/atomic_file.h"
#include "render/video.h"

namespace collido::render {
namespace {

std::string av_error(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, buf, sizeof buf);
  return buf;
}

// The encoder for a codec: the named library encoder Debian ships (libx264,
// libvpx-vp9), else whatever libavcodec registers for the codec id.
// libx264 and libvpx print several lines of statistics per file at the default
// level; errors are all the command line and the service need to show.
void quiet_libav_logs() {
  static std::once_flag once;
  std::call_once(once, [] { av_log_set_level(AV_LOG_ERROR); });
}

const AVCodec* find_encoder(VideoCodec codec) {
  if (codec == VideoCodec::kGif) return avcodec_find_encoder(AV_CODEC_ID_GIF);
  const char* preferred = codec == VideoCodec::kH264 ? "libx264" : "libvpx-vp9";
  if (const AVCodec* c = avcodec_find_encoder_by_name(preferred)) return c;
  return avcodec_find_encoder(codec == VideoCodec::kH264 ? AV_CODEC_ID_H264 : AV_CODEC_ID_VP9);
}

}  // namespace

const char* video_extension(VideoCodec codec) {
  switch (codec) {
    case VideoCodec::kH264: return "mp4";
    case VideoCodec::kVP9: return "webm";
    case VideoCodec::kGif: return "gif";
  }
  return "bin";
}

struct VideoWriter::Impl {
  VideoOptions options;
  std::string path, tmp_path;
  AVFormatContext* format = nullptr;
  AVCodecContext* codec = nullptr;
  AVStream* stream = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  SwsContext* sws = nullptr;
  int64_t next_pts = 0;
  bool header_written = false;
  bool finished = false;

  ~Impl() {
    if (format && format->pb) avio_closep(&format->pb);
    avformat_free_context(format);
    avcodec_free_context(&codec);
    av_frame_free(&frame);
    av_packet_free(&packet);
    sws_freeContext(sws);
    if (!finished && !tmp_path.empty()) std::remove(tmp_path.c_str());
  }

  // Moves every packet the encoder has ready into the file.
  Status drain() {
    for (;;) {
      int rc = avcodec_receive_packet(codec, packet);
      if (rc == AVERROR(EAGAIN) || rc == AVERROR_EOF) return Status::ok();
      if (rc < 0) return backend_error(path + ": encoder failed: " + av_error(rc));
      av_packet_rescale_ts(packet, codec->time_base, stream->time_base);
      packet->stream_index = stream->index;
      rc = av_interleaved_write_frame(format, packet);  // takes the packet's reference
      if (rc < 0) return backend_error(path + ": cannot write packet: " + av_error(rc));
    }
  }
};

VideoWriter::VideoWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
VideoWriter::~VideoWriter() = default;

std::unique_ptr<VideoWriter> VideoWriter::open(const std::string& path, const VideoOptions& o,
                                               Status* status) {
  auto fail = [&](const std::string& msg) -> std::unique_ptr<VideoWriter> {
    if (status) *status = backend_error(msg);
    return nullptr;
  };
  const bool gif = o.codec == VideoCodec::kGif;
  if (o.width <= 0 || o.height <= 0 || (!gif && (o.width % 2 || o.height % 2)))
    return fail(path + ": video size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                " must be positive and even (yuv420p)");
  if (o.source_width < 0 || o.source_height < 0 || (o.source_width > 0) != (o.source_height > 0))
    return fail(path + ": source size must be given as both width and height, or neither");
  if (o.fps <= 0 || o.fps > 240) return fail(path + ": fps must be in 1..240");
  if (o.fps_divisor < 1 || o.fps_divisor > o.fps)
    return fail(path + ": fps_divisor must be in 1..fps");

  quiet_libav_logs();
  auto impl = std::make_unique<Impl>();
  impl->options = o;
  impl->path = path;
  impl->tmp_path = temp_path_for(path);
  const bool h264 = o.codec == VideoCodec::kH264;
  const char* muxer = video_extension(o.codec);
  if (o.source_width == 0) impl->options.source_width = o.width;
  if (o.source_height == 0) impl->options.source_height = o.height;

  const AVCodec* enc = find_encoder(o.codec);
  if (!enc)
    return fail(std::string("this libavcodec has no ") + (h264 ? "H.264" : gif ? "GIF" : "VP9") +
                " encoder");
  int rc = avformat_alloc_output_context2(&impl->format, nullptr, muxer, impl->tmp_path.c_str());
  if (rc < 0 || !impl->format) return fail(path + ": no " + muxer + " muxer: " + av_error(rc));

  AVCodecContext* c = impl->codec = avcodec_alloc_context3(enc);
  if (!c) return fail(path + ": out of memory");
  c->width = o.width;
  c->height = o.height;
  // The exact rate, not a rounded one: the GIF muxer keeps its delays in
  // centiseconds, rounding each frame's time, so their mean is this rate.
  c->framerate = av_make_q(o.fps, o.fps_divisor);
  av_reduce(&c->framerate.num, &c->framerate.den, o.fps, o.fps_divisor, 1 << 16);
  c->time_base = av_inv_q(c->framerate);
  // GIF: a fixed 3-3-2 palette with swscale's dithering needs no palette pass
  // over the whole clip, so frames are still encoded as they arrive.
  c->pix_fmt = gif ? AV_PIX_FMT_RGB8 : AV_PIX_FMT_YUV420P;
  // A key frame every 2 s keeps seeking in the browser quick.
  c->gop_size = std::max(1, 2 * o.fps / o.fps_divisor);
  c->thread_count = gif ? 1 : o.threads;
  if (!gif) {
    // Tag the stream as BT.709 limited range, matching the swscale conversion,
    // so players do not guess the colours.
    c->color_range = AVCOL_RANGE_MPEG;
    c->colorspace = AVCOL_SPC_BT709;
    c->color_primaries = AVCOL_PRI_BT709;
    c->color_trc = AVCOL_TRC_BT709;
  }
  if (impl->format->oformat->flags & AVFMT_GLOBALHEADER) c->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;

  AVDictionary* opts = nullptr;
  if (h264) {
    // veryfast keeps 720p encoding well above real time on two cores; the
    // particle scenes are mostly flat background, so quality stays high.
    av_dict_set(&opts, "preset", "veryfast", 0);
    av_dict_set_int(&opts, "crf", o.crf >= 0 ? o.crf : 20, 0);
    av_dict_set(&opts, "profile", "high", 0);
  } else if (!gif) {
    // libvpx's default "good" mode is far too slow for a render job; realtime
    // with cpu-used 8 and row threading is fast and still looks clean.
    c->bit_rate = 0;  // with crf: constant quality
    av_dict_set(&opts, "deadline", "realtime", 0);
    av_dict_set(&opts, "cpu-used", "8", 0);
    av_dict_set(&opts, "row-mt", "1", 0);
    av_dict_set(&opts, "tile-columns", "2", 0);
    av_dict_set_int(&opts, "crf", o.crf >= 0 ? o.crf : 30, 0);
  }
  rc = avcodec_open2(c, enc, &opts);
  av_dict_free(&opts);
  if (rc < 0) return fail(path + ": cannot open encoder " + enc->name + ": " + av_error(rc));

  impl->stream = avformat_new_stream(impl->format, nullptr);
  if (!impl->stream) return fail(path + ": cannot add a video stream");
  impl->stream->time_base = c->time_base;
  impl->stream->avg_frame_rate = c->framerate;
  rc = avcodec_parameters_from_context(impl->stream->codecpar, c);
  if (rc < 0) return fail(path + ": " + av_error(rc));

  rc = avio_open(&impl->format->pb, impl->tmp_path.c_str(), AVIO_FLAG_WRITE);
  if (rc < 0) return fail("cannot create " + impl->tmp_path + ": " + av_error(rc));
  AVDictionary* mux_opts = nullptr;
  if (h264) av_dict_set(&mux_opts, "movflags", "+faststart", 0);
  rc = avformat_write_header(impl->format, &mux_opts);
  av_dict_free(&mux_opts);
  if (rc < 0) return fail(path + ": cannot write header: " + av_error(rc));
  impl->header_written = true;

  impl->frame = av_frame_alloc();
  impl->packet = av_packet_alloc();
  if (!impl->frame || !impl->packet) return fail(path + ": out of memory");
  impl->frame->format = c->pix_fmt;
  impl->frame->width = o.width;
  impl->frame->height = o.height;
  if (av_frame_get_buffer(impl->frame, 0) < 0) return fail(path + ": out of memory");
  const VideoOptions& io = impl->options;
  impl->sws = sws_getContext(io.source_width, io.source_height, AV_PIX_FMT_RGB24, o.width,
                             o.height, c->pix_fmt, gif ? SWS_AREA : SWS_BILINEAR, nullptr, nullptr,
                             nullptr);
  if (!impl->sws) return fail(path + ": swscale cannot convert the RGB24 frames");
  if (!gif) {
    const int* bt709 = sws_getCoefficients(SWS_CS_ITU709);
    sws_setColorspaceDetails(impl->sws, bt709, 1 /*full-range RGB in*/, bt709, 0 /*limited out*/,
                             0, 1 << 16, 1 << 16);
  }
  if (status) *status = Status::ok();
  return std::unique_ptr<VideoWriter>(new VideoWriter(std::move(impl)));
}

Status VideoWriter::add_frame(const Image& image) {
  Impl& s = *impl_;
  if (s.finished) return backend_error(s.path + ": add_frame after finish");
  if (image.width != s.options.source_width || image.height != s.options.source_height ||
      image.rgb.size() != size_t(image.width) * image.height * 3)
    return backend_error(s.path + ": frame is " + std::to_string(image.width) + "x" +
                         std::to_string(image.height) + ", the writer takes " +
                         std::to_string(s.options.source_width) + "x" +
                         std::to_string(s.options.source_height));
  // The encoder may still hold the previous picture; get a private buffer if so.
  int rc = av_frame_make_writable(s.frame);
  if (rc < 0) return backend_error(s.path + ": " + av_error(rc));
  const uint8_t* src[1] = {image.rgb.data()};
  const int stride[1] = {image.width * 3};
  // Every output row, or the frame would carry the last one's pixels.
  if (sws_scale(s.sws, src, stride, 0, image.height, s.frame->data, s.frame->linesize) !=
      s.frame->height)
    return backend_error(s.path + ": swscale could not convert a frame");
  s.frame->pts = s.next_pts++;
  rc = avcodec_send_frame(s.codec, s.frame);
  if (rc < 0) return backend_error(s.path + ": encoder refused a frame: " + av_error(rc));
  return s.drain();
}

Status VideoWriter::finish() {
  Impl& s = *impl_;
  if (s.finished) return Status::ok();
  int rc = avcodec_send_frame(s.codec, nullptr);
  if (rc < 0 && rc != AVERROR_EOF) return backend_error(s.path + ": " + av_error(rc));
  if (Status st = s.drain(); !st) return st;
  rc = av_write_trailer(s.format);
  if (rc < 0) return backend_error(s.path + ": cannot write trailer: " + av_error(rc));
  rc = avio_closep(&s.format->pb);
  if (rc < 0) return backend_error(s.path + ": close failed: " + av_error(rc));
  if (std::rename(s.tmp_path.c_str(), s.path.c_str()) != 0)
    return backend_error("cannot rename " + s.tmp_path + " to " + s.path);
  s.finished = true;
  return Status::ok();
}

int VideoWriter::frames_written() const {
  return static_cast<int>(impl_->next_pts);
}
std::string VideoWriter::encoder_name() const {
  return impl_->codec->codec->name;
}

namespace {

// True when the top-level "moov" box comes before "mdat" (a +faststart MP4).
bool moov_before_mdat(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  bool result = false;
  for (int i = 0; i < 64; ++i) {
    unsigned char h[16];
    if (std::fread(h, 1, 8, f) != 8) break;
    uint64_t size = (uint64_t(h[0]) << 24) | (h[1] << 16) | (h[2] << 8) | h[3];
    const std::string type(reinterpret_cast<char*>(h + 4), 4);
    uint64_t header = 8;
    if (size == 1) {  // 64-bit size follows
      if (std::fread(h + 8, 1, 8, f) != 8) break;
      size = 0;
      for (int k = 8; k < 16; ++k) size = (size << 8) | h[k];
      header = 16;
    }
    if (type == "moov") {
      result = true;
      break;
    }
    if (type == "mdat" || size < header) break;
    if (std::fseek(f, long(size - header), SEEK_CUR) != 0) break;
  }
  std::fclose(f);
  return result;
}

// An opened video stream and its decoder, closed on destruction. probe_video
// and read_video_frame share it: both open, then walk the decoded frames.
struct Decoder {
  std::string path;
  AVFormatContext* fmt = nullptr;
  AVCodecContext* dec = nullptr;
  AVPacket* pkt = nullptr;
  AVFrame* frame = nullptr;
  int stream = -1;

  ~Decoder() {
    av_frame_free(&frame);
    av_packet_free(&pkt);
    avcodec_free_context(&dec);
    avformat_close_input(&fmt);
  }

  Status open(const std::string& p) {
    quiet_libav_logs();
    path = p;
    int rc = avformat_open_input(&fmt, path.c_str(), nullptr, nullptr);
    if (rc < 0) return backend_error("cannot open video " + path + ": " + av_error(rc));
    if ((rc = avformat_find_stream_info(fmt, nullptr)) < 0)
      return backend_error(path + ": no stream info: " + av_error(rc));
    const AVCodec* decoder = nullptr;
    stream = av_find_best_stream(fmt, AVMEDIA_TYPE_VIDEO, -1, -1, &decoder, 0);
    if (stream < 0 || !decoder) return backend_error(path + ": no decodable video stream");
    dec = avcodec_alloc_context3(decoder);
    if (!dec) return backend_error(path + ": out of memory");
    if ((rc = avcodec_parameters_to_context(dec, fmt->streams[stream]->codecpar)) < 0)
      return backend_error(path + ": bad stream parameters: " + av_error(rc));
    if ((rc = avcodec_open2(dec, decoder, nullptr)) < 0)
      return backend_error(path + ": cannot open decoder: " + av_error(rc));
    pkt = av_packet_alloc();
    frame = av_frame_alloc();
    if (!pkt || !frame) return backend_error(path + ": out of memory");
    return Status::ok();
  }

  // Decodes frames in order, calling on_frame(frame) until it returns false or
  // the stream ends (the decoder is flushed at the end).
  template <class F>
  Status for_each_frame(F&& on_frame) {
    bool flushing = false;
    for (;;) {
      int rc = avcodec_receive_frame(dec, frame);
      if (rc == 0) {
        if (!on_frame(frame)) return Status::ok();
        continue;
      }
      if (rc == AVERROR_EOF) return Status::ok();
      if (rc != AVERROR(EAGAIN)) return backend_error(path + ": decoding failed: " + av_error(rc));
      if (flushing) return Status::ok();
      // The decoder wants input: the next packet of our stream, or a flush.
      for (;;) {
        rc = av_read_frame(fmt, pkt);
        // The end of the file flushes the decoder; a read error is one (a
        // video cut short must not probe as a shorter whole one).
        if (rc < 0 && rc != AVERROR_EOF)
          return backend_error(path + ": cannot read: " + av_error(rc));
        if (rc < 0) {
          avcodec_send_packet(dec, nullptr);
          flushing = true;
          break;
        }
        const bool ours = pkt->stream_index == stream;
        if (ours) rc = avcodec_send_packet(dec, pkt);
        av_packet_unref(pkt);
        if (ours) {
          if (rc < 0 && rc != AVERROR(EAGAIN)) return backend_error(path + ": corrupt packet: " + av_error(rc));
          break;
        }
      }
    }
  }
};

}  // namespace

Status probe_video(const std::string& path, VideoInfo* info) {
  Decoder d;
  if (Status s = d.open(path); !s) return s;
  const AVStream* st = d.fmt->streams[d.stream];
  VideoInfo out;
  out.container = d.fmt->iformat->name;
  out.codec = avcodec_get_name(st->codecpar->codec_id);
  out.width = st->codecpar->width;
  out.height = st->codecpar->height;
  if (const char* pf = av_get_pix_fmt_name(AVPixelFormat(st->codecpar->format)))
    out.pixel_format = pf;
  if (d.fmt->duration > 0)
    out.duration_s = double(d.fmt->duration) / AV_TIME_BASE;
  else if (st->duration > 0)
    out.duration_s = st->duration * av_q2d(st->time_base);
  if (st->avg_frame_rate.den) out.fps = av_q2d(st->avg_frame_rate);
  if (Status s = d.for_each_frame([&](AVFrame*) { return ++out.frames, true; }); !s) return s;
  if (out.container.find("mp4") != std::string::npos) out.index_at_front = moov_before_mdat(path);
  *info = out;
  return Status::ok();
}

Status read_video_frame(const std::string& path, int index, Image* image) {
  Decoder d;
  if (Status s = d.open(path); !s) return s;
  int seen = 0;
  bool found = false;
  Status convert = Status::ok();
  Status walked = d.for_each_frame([&](AVFrame* f) {
    if (seen++ < index) return true;
    found = true;
    SwsContext* sws = sws_getContext(f->width, f->height, AVPixelFormat(f->format), f->width, f->height,
                                     AV_PIX_FMT_RGB24, SWS_BILINEAR, nullptr, nullptr, nullptr);
    if (!sws) {
      convert = backend_error(path + ": cannot convert the frame to RGB");
      return false;
    }
    const int space = f->colorspace == AVCOL_SPC_BT709 ? SWS_CS_ITU709 : SWS_CS_ITU601;
    const int* coeffs = sws_getCoefficients(space);
    sws_setColorspaceDetails(sws, coeffs, f->color_range == AVCOL_RANGE_JPEG, coeffs, 1, 0, 1 << 16, 1 << 16);
    Image out;
    out.resize(f->width, f->height);
    uint8_t* dst[1] = {out.rgb.data()};
    const int stride[1] = {f->width * 3};
    sws_scale(sws, f->data, f->linesize, 0, f->height, dst, stride);
    sws_freeContext(sws);
    *image = std::move(out);
    return false;
  });
  if (!walked) return walked;
  if (!convert) return convert;
  if (!found)
    return backend_error(path + ": has " + std::to_string(seen) + " frames, no frame " + std::to_string(index));
  return Status::ok();
}

}  // namespace collido::render
