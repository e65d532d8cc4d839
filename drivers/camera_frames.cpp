#include "drivers/camera_frames.hpp"

#include <opencv2/imgproc.hpp>

namespace stereod::drivers {

camera::Mosaic parse_mosaic(const std::string &bayer, const std::string &section)
{
	if (bayer == "none" || bayer == "auto")
		return camera::Mosaic::None;
	if (bayer == "RGGB")
		return camera::Mosaic::RGGB;
	if (bayer == "GRBG")
		return camera::Mosaic::GRBG;
	if (bayer == "GBRG")
		return camera::Mosaic::GBRG;
	if (bayer == "BGGR")
		return camera::Mosaic::BGGR;
	throw SourceError(section + ".bayer = \"" + bayer + "\": must be auto, none, RGGB, GRBG, GBRG or BGGR");
}

PixelFormat choose_output(const std::string &color, camera::Mosaic mosaic, bool rgb, const std::string &section)
{
	if (color == "mono")
		return PixelFormat::Mono8;
	if (color == "bgr")
		return PixelFormat::Bgr8;
	if (color == "auto")
		return mosaic != camera::Mosaic::None || rgb ? PixelFormat::Bgr8 : PixelFormat::Mono8;
	throw SourceError(section + ".color = \"" + color + "\": must be auto, mono or bgr");
}

void fill_eyes(const PixelRecipe &recipe, const uint8_t *data, size_t size, int width, int height, EyeScratch &scratch,
	       cv::Mat &left, cv::Mat *right)
{
	const size_t stride = static_cast<size_t>(width) * static_cast<size_t>(recipe.bytes_per_pixel);
	if (size < stride * static_cast<size_t>(height))
		throw std::runtime_error("buffer of " + std::to_string(size) + " bytes is shorter than " +
					 std::to_string(width) + "x" + std::to_string(height) + "x" +
					 std::to_string(recipe.bytes_per_pixel));
	// The buffer, seen as an image without copying it.
	const cv::Mat whole(height, width, recipe.rgb ? CV_8UC3 : (recipe.bytes_per_pixel == 2 ? CV_16UC1 : CV_8UC1),
			    const_cast<uint8_t *>(data), stride);
	switch (recipe.layout) {
	case camera::StereoLayout::Interleaved16: {
		camera::deinterleave16(data, width, height, stride, scratch.first, scratch.second);
		const cv::Mat &l = recipe.first_is_left ? scratch.first : scratch.second;
		const cv::Mat &r = recipe.first_is_left ? scratch.second : scratch.first;
		camera::develop(l, recipe.mosaic, recipe.output, left);
		if (right)
			camera::develop(r, recipe.mosaic, recipe.output, *right);
		return;
	}
	case camera::StereoLayout::SideBySide:
	case camera::StereoLayout::TopBottom: {
		if (recipe.bytes_per_pixel != 1)
			throw std::runtime_error("side_by_side and top_bottom need an 8-bit stream");
		const auto [l, r] = camera::split_views(whole, recipe.layout);
		camera::develop(l, recipe.mosaic, recipe.output, left);
		if (right)
			camera::develop(r, recipe.mosaic, recipe.output, *right);
		return;
	}
	case camera::StereoLayout::Pair:
		break;
	}
	// One eye per camera.
	if (recipe.rgb) {
		if (recipe.output == PixelFormat::Bgr8)
			cv::cvtColor(whole, left, cv::COLOR_RGB2BGR);
		else
			cv::cvtColor(whole, left, cv::COLOR_RGB2GRAY);
		return;
	}
	if (recipe.bytes_per_pixel == 2) {
		camera::high_bytes(data, width, height, stride, scratch.first);
		camera::develop(scratch.first, recipe.mosaic, recipe.output, left);
		return;
	}
	camera::develop(whole, recipe.mosaic, recipe.output, left);
}

} // namespace stereod::drivers
