#include "core/camera/layout.hpp"

#include <cstring>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace stereod::camera {

std::optional<StereoLayout> parse_layout(std::string_view name) noexcept
{
	if (name == "pair")
		return StereoLayout::Pair;
	if (name == "interleaved16")
		return StereoLayout::Interleaved16;
	if (name == "side_by_side")
		return StereoLayout::SideBySide;
	if (name == "top_bottom")
		return StereoLayout::TopBottom;
	return std::nullopt;
}

std::string_view to_string(StereoLayout layout) noexcept
{
	switch (layout) {
	case StereoLayout::Pair:
		return "pair";
	case StereoLayout::Interleaved16:
		return "interleaved16";
	case StereoLayout::SideBySide:
		return "side_by_side";
	case StereoLayout::TopBottom:
		return "top_bottom";
	}
	return "?";
}

cv::Size eye_size(StereoLayout layout, int width, int height) noexcept
{
	switch (layout) {
	case StereoLayout::SideBySide:
		return {width / 2, height};
	case StereoLayout::TopBottom:
		return {width, height / 2};
	case StereoLayout::Pair:
	case StereoLayout::Interleaved16:
		break;
	}
	return {width, height};
}

void deinterleave16(const uint8_t *data, int width, int height, size_t stride, cv::Mat &first, cv::Mat &second)
{
	if (first.cols != width || first.rows != height || first.type() != CV_8UC1 || second.size() != first.size() ||
	    second.type() != CV_8UC1)
		throw std::invalid_argument("deinterleave16: outputs must be preallocated CV_8UC1 at the input size");
	// OpenCV's split of a two-channel view is SIMD (byte shuffles); a plain loop with a stride of two was not
	// vectorised by GCC and cost twice as much (bench_camera_pixels). The outputs are reused, never reallocated.
	const cv::Mat pairs(height, width, CV_8UC2, const_cast<uint8_t *>(data), stride);
	cv::Mat eyes[2] = {first, second};
	cv::split(pairs, eyes);
	if (eyes[0].data != first.data || eyes[1].data != second.data)
		throw std::logic_error("deinterleave16: output was reallocated");
}

std::pair<cv::Mat, cv::Mat> split_views(const cv::Mat &image, StereoLayout layout)
{
	if (layout == StereoLayout::SideBySide) {
		const int half = image.cols / 2;
		return {image(cv::Rect(0, 0, half, image.rows)), image(cv::Rect(half, 0, half, image.rows))};
	}
	if (layout == StereoLayout::TopBottom) {
		const int half = image.rows / 2;
		return {image(cv::Rect(0, 0, image.cols, half)), image(cv::Rect(0, half, image.cols, half))};
	}
	throw std::invalid_argument("split_views: only side_by_side and top_bottom images hold two views");
}

namespace {

/// OpenCV names Bayer patterns by the second row's first two pixels, so the sensor's RGGB is its BayerBG.
int demosaic_code(Mosaic mosaic, PixelFormat format)
{
	const bool colour = format == PixelFormat::Bgr8;
	switch (mosaic) {
	case Mosaic::RGGB:
		return colour ? cv::COLOR_BayerBG2BGR : cv::COLOR_BayerBG2GRAY;
	case Mosaic::GRBG:
		return colour ? cv::COLOR_BayerGB2BGR : cv::COLOR_BayerGB2GRAY;
	case Mosaic::GBRG:
		return colour ? cv::COLOR_BayerGR2BGR : cv::COLOR_BayerGR2GRAY;
	case Mosaic::BGGR:
		return colour ? cv::COLOR_BayerRG2BGR : cv::COLOR_BayerRG2GRAY;
	case Mosaic::None:
		break;
	}
	return -1;
}

} // namespace

void develop(const cv::Mat &raw, Mosaic mosaic, PixelFormat format, cv::Mat &out)
{
	if (raw.type() != CV_8UC1 || out.size() != raw.size() || out.type() != cv_type(format))
		throw std::invalid_argument("develop: raw must be CV_8UC1 and out preallocated at its size");
	const void *before = out.data;
	if (mosaic != Mosaic::None)
		cv::cvtColor(raw, out, demosaic_code(mosaic, format));
	else if (format == PixelFormat::Bgr8)
		cv::cvtColor(raw, out, cv::COLOR_GRAY2BGR);
	else
		raw.copyTo(out);
	if (out.data != before) // cvtColor reuses a buffer of the right size and type; make sure it did
		throw std::logic_error("develop: output was reallocated");
}

void high_bytes(const uint8_t *data, int width, int height, size_t stride, cv::Mat &out)
{
	if (out.cols != width || out.rows != height || out.type() != CV_8UC1)
		throw std::invalid_argument("high_bytes: output must be preallocated CV_8UC1 at the input size");
	for (int y = 0; y < height; ++y) {
		const uint8_t *in = data + static_cast<size_t>(y) * stride;
		uint8_t *o = out.ptr<uint8_t>(y);
		for (int x = 0; x < width; ++x)
			o[x] = in[2 * x + 1]; // little-endian samples: byte 1 is the high byte
	}
}

} // namespace stereod::camera
