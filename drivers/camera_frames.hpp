#pragma once
// What every camera driver shares between "a buffer arrived" and "a frame is in the pool": the pixel
// recipe (layout, byte order, mosaic, output format) chosen once at open, the per-camera clock and frame
// counter, and the counters that end up in `status`.
#include <atomic>
#include <cstdint>
#include <string>

#include "core/camera/layout.hpp"
#include "core/camera/timing.hpp"
#include "core/frame.hpp"
#include "drivers/source.hpp"

namespace stereod::drivers {

/// How one camera's raw pixels become the frame's eyes. Chosen at open from the config and the camera's pixel
/// format; applied to every buffer by fill_eyes().
struct PixelRecipe {
	camera::StereoLayout layout = camera::StereoLayout::Pair;
	int bytes_per_pixel = 1;    ///< of the camera's stream: 1 (8-bit), 2 (16-bit), 3 (RGB8)
	bool rgb = false;	    ///< the stream is RGB8 (pair layout)
	bool first_is_left = false; ///< interleaved16: byte 0 of each pixel is the left eye
	camera::Mosaic mosaic = camera::Mosaic::None;
	PixelFormat output = PixelFormat::Mono8;
};

/// Parses the config's colour words. Throws SourceError naming `section`.
camera::Mosaic parse_mosaic(const std::string &bayer, const std::string &section);
PixelFormat choose_output(const std::string &color, camera::Mosaic mosaic, bool rgb, const std::string &section);

/// Scratch images for the eyes before demosaicing, allocated once at open.
struct EyeScratch {
	cv::Mat first, second;
	void allocate(cv::Size eye)
	{
		first.create(eye, CV_8UC1);
		second.create(eye, CV_8UC1);
	}
};

/// Writes the eyes carried by one buffer (the whole stereo pair, or with Pair layout one eye into `left`)
/// into frame images. At most one pass over the pixels for monochrome, two with a mosaic after
/// de-interleaving. Throws std::runtime_error when the buffer is shorter than its geometry needs.
void fill_eyes(const PixelRecipe &recipe, const uint8_t *data, size_t size, int width, int height, EyeScratch &scratch,
	       cv::Mat &left, cv::Mat *right);

} // namespace stereod::drivers
