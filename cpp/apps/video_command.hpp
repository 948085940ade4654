#pragma once
// `pnet video DIR [--out FILE.mp4] [--fps F]`: the frame_NNNNN.png images of a run, encoded by
// ffmpeg (H.264, yuv420p: plays in browsers and slides) into one MP4.
namespace pnet::apps {

/// argv[0] is "video". The frame rate defaults to 1 / frame_dt from DIR/run.json (real time), else
/// 50. Frames are taken in number order from the first one present; a gap in the numbering is an
/// error (a run still being written, or a deleted frame). The video is encoded to a temporary file
/// and renamed into place, so an existing FILE is replaced only by a complete video. Returns the
/// process exit code: 0 written, 1 ffmpeg is missing or failed, 2 bad input (usage, no frames, a gap).
int video_command(int argc, char** argv);

}  // namespace pnet::apps
