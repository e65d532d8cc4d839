#pragma once
// Seed 001's semantic prior (section III.C.1.b): feature points on things that move by themselves (people)
// form the "dynamic category". They take no part in estimating the camera's motion (the homography fit of
// seed 000 and the stereo pose), so a crowd cannot drag the static scene's motion along, and are then judged
// by the geometric tests like any other point, or (seed 001 as written) labelled dynamic outright.
//
// The detector is OpenCV's HOG people detector (Dalal & Triggs 2005; its linear SVM is compiled into OpenCV,
// nothing to download). It costs tens of milliseconds per VGA frame, so it runs on every k-th frame
// (`prior.every_n_frames`) and the frames between carry its boxes forward by the motion of the points
// inside them.
#include <cstdint>
#include <span>
#include <vector>

#include <opencv2/core.hpp>

namespace stereod::vision {

enum class PriorCategory : uint8_t {
	Dynamic,	    ///< moves by itself: people (seed 001: people, cats, dogs)
	PotentiallyDynamic, ///< can be moved: chairs, monitors (needs a detector that knows them)
};

/// What a point in a dynamic-category region is labelled.
enum class PriorLabelRule : uint8_t {
	Judged,	  ///< left out of the motion fits, labelled by the tests like every point
	Weighted, ///< judged, but the motion memory's gate is `memory_chi2` in a person box: the prior odds of
		  ///< motion are higher there, so less evidence decides (a likelihood-ratio test with a prior)
	Dynamic,  ///< seed 001 as written: labelled dynamic whatever the tests say (a standing person too)
};

struct PersonPriorParams {
	bool enabled = false;
	int every_n_frames = 5;	 ///< detect on frames whose sequence number is a multiple of this
	double min_score = 1.0;	 ///< the SVM's margin a detection needs (OpenCV's default detector: ~0 to ~5)
	double upscale = 1.0;	 ///< detect on the image scaled by this (HOG's window is 64 x 128 pixels)
	double margin = 0.05;	 ///< boxes grow by this fraction of their size on each side
	int max_age_frames = 10; ///< a carried box is forgotten after this many frames without a detection
	PriorLabelRule rule = PriorLabelRule::Judged;
	double memory_chi2 = 2.0; ///< Weighted: the memory's gate in a person box (memory.chi2 elsewhere)
};

/// One region of the prior, in the left image's pixels.
struct PriorRegion {
	cv::Rect2f box;
	float score = 0;
	PriorCategory category = PriorCategory::Dynamic;
	int age_frames = 0; ///< frames since the detector saw it (0: detected in this frame)
};

/// People in a grey image: HOG + linear SVM over a scale pyramid, overlapping windows grouped, each kept when
/// its margin reaches `min_score`, grown by `margin`. Nothing for an empty image.
std::vector<PriorRegion> detect_people(const cv::Mat &grey, const PersonPriorParams &params);

/// Frame n-1's regions carried to frame n: each box moves by the median displacement of the matches that
/// start inside it (unmoved when none do) and ages by one; boxes older than `max_age_frames` are dropped.
std::vector<PriorRegion> carry_regions(std::span<const PriorRegion> regions, std::span<const cv::Point2f> from,
				       std::span<const cv::Point2f> to, int max_age_frames);

/// Per point: 1 where it lies in a region of the dynamic category.
std::vector<uint8_t> in_dynamic_category(std::span<const cv::Point2f> points, std::span<const PriorRegion> regions);

} // namespace stereod::vision
