#pragma once
// A reference of moving pixels for footage from a camera that stands still (OpenCV's vtest.avi): the
// per-pixel median of frames sampled across the whole video is the empty scene, and a pixel that differs
// from it is on something that moved there. Independent of every method stereod runs (no features, no
// matching), so it can score them on real footage where no ground truth exists. Its limits, documented in
// docs/classification.md: someone who stands still for most of the video is part of the median (not a
// mover), shadows count as movers, and a camera that moves makes it meaningless.
#include <span>

#include <opencv2/core.hpp>

namespace stereod::tools {

struct MotionReferenceParams {
	int threshold = 30;	  ///< largest colour-channel difference from the background that is still background
	int min_area_px = 150;	  ///< smaller blobs are noise (compression, swaying leaves)
	int close_radius_px = 3;  ///< fills a person's body between the parts that differ from the background
	int dilate_radius_px = 1; ///< a feature point on a mover's outline is located within a pixel or two
};

/// The per-pixel, per-channel median of `samples` (all the same size and type, CV_8UC1 or CV_8UC3).
cv::Mat median_background(std::span<const cv::Mat> samples);

/// Movers in `frame` against `background`: CV_8UC1, 0 on the scene and 1..N on the N blobs kept (numbered
/// in this frame only: the ids do not follow a mover from frame to frame).
cv::Mat mover_mask(const cv::Mat &frame, const cv::Mat &background, const MotionReferenceParams &params);

} // namespace stereod::tools
