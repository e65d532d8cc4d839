#pragma once
// How one camera stream carries a stereo pair, and how raw sensor pixels become the frame's images. Pure
// functions over pixels: the drivers (Aravis, libdc1394, V4L2) hand their buffers in, the frame pool's images
// come out, so every byte path is tested on constructed data without a camera.
#include <cstdint>
#include <optional>
#include <string_view>

#include <opencv2/core.hpp>

#include "core/frame.hpp"

namespace stereod::camera {

enum class StereoLayout : uint8_t {
	Pair,	       ///< two cameras (or devices), one eye each
	Interleaved16, ///< one 16-bit stream, each pixel's two bytes are the two eyes (Point Grey Bumblebee)
	SideBySide,    ///< one image, left eye in the left half (the usual UVC stereo camera)
	TopBottom,     ///< one image, left eye in the top half
};

/// The colour filter in front of a sensor. None is a monochrome sensor.
enum class Mosaic : uint8_t { None, RGGB, GRBG, GBRG, BGGR };

std::optional<StereoLayout> parse_layout(std::string_view name) noexcept;
std::string_view to_string(StereoLayout layout) noexcept;

/// Size of one eye's image for a camera image of `width` x `height` in `layout`.
cv::Size eye_size(StereoLayout layout, int width, int height) noexcept;

/// Splits a pixel-interleaved 16-bit image (`width` pixels of 2 bytes per row, `stride` bytes between rows):
/// byte 0 of every pixel goes to `first`, byte 1 to `second`. Both outputs must already be width x height
/// CV_8UC1: nothing is allocated.
void deinterleave16(const uint8_t *data, int width, int height, size_t stride, cv::Mat &first, cv::Mat &second);

/// Views of the two eyes inside one side-by-side or top-bottom image (no copy).
std::pair<cv::Mat, cv::Mat> split_views(const cv::Mat &image, StereoLayout layout);

/// Writes one eye's raw 8-bit image into a frame image of `format`: a copy for monochrome into Mono8, the
/// grey replicated into Bgr8, Bayer demosaiced (bilinear, OpenCV) into Bgr8 or to grey into Mono8. `out` is
/// preallocated at raw's size and the format's type; it is never reallocated.
void develop(const cv::Mat &raw, Mosaic mosaic, PixelFormat format, cv::Mat &out);

/// The most significant byte of each 16-bit sample (Mono16 cameras feeding an 8-bit pipeline).
void high_bytes(const uint8_t *data, int width, int height, size_t stride, cv::Mat &out);

} // namespace stereod::camera
