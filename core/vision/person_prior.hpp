#pragma once
// Seed 001's semantic prior (section III.C.1.b): feature points on things that move by themselves (people)
// form the "dynamic category". They take no part in estimating the camera's motion (the homography fit of
// seed 000 and the stereo pose), so a crowd cannot drag the static scene's motion along, and are then judged
// by the geometric tests like any other point, or (seed 001 as written) labelled dynamic outright.
//
// The detector is OpenCV's HOG people detector (Dalal & Triggs 2005; its linear SVM is compiled into OpenCV,
// nothing to download). It costs tens of milliseconds per VGA frame, so it runs on every k-th frame
// (`prior.every_n_frames`) and the frames between carry its boxes forward by the motion of the points
// inside them. A user-supplied ONNX detector or segmentation network can take its place (prior_model.hpp); it
// also knows the potentially dynamic category (chairs), whose objects are judged by a vote of their points.
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/result.hpp"

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

/// The detector.
enum class PriorDetector : uint8_t {
	Hog,  ///< OpenCV's HOG people detector: no weights, people only
	Onnx, ///< a user-supplied model (prior_model.hpp)
};

/// How the model's output is laid out.
enum class ModelLayout : uint8_t {
	Yolov8,	      ///< 1 x (4 + C) x N: per candidate cx, cy, w, h (input pixels), then C class scores
	Yolov5,	      ///< 1 x N x (5 + C): cx, cy, w, h, objectness, then C class scores (score = obj x class)
	Segmentation, ///< 1 x C x h x w class scores (argmax per pixel), or 1 x 1 x h x w class ids
};

/// One of the model's classes and the prior's category it stands for.
struct ModelClass {
	int id = 0;
	PriorCategory category = PriorCategory::Dynamic;
	bool operator==(const ModelClass &) const = default;
};

struct PriorModelSpec {
	ModelLayout layout = ModelLayout::Yolov8;
	int input_width = 640; ///< the network's input; the image is scaled to fit and padded (letterbox)
	int input_height = 640;
	double input_scale = 1.0 / 255; ///< pixel values times this (most exports expect 0..1)
	bool swap_rb = true;		///< the network wants RGB (OpenCV's images are BGR)
	double min_confidence = 0.5;	///< detectors: a candidate's score must reach this
	double nms_iou = 0.45;		///< detectors: of two boxes of one class overlapping more, the weaker goes
	int min_region_px = 64;		///< segmentation: smaller connected regions (image pixels) are dropped
	/// COCO's class 0 is "person": the default fits the common detector exports.
	std::vector<ModelClass> classes = {{0, PriorCategory::Dynamic}};
};

class PriorModel;

struct PersonPriorParams {
	bool enabled = false;
	int every_n_frames = 5;	 ///< detect on frames whose sequence number is a multiple of this
	double min_score = 1.0;	 ///< the SVM's margin a detection needs (OpenCV's default detector: ~0 to ~5)
	double upscale = 1.0;	 ///< detect on the image scaled by this (HOG's window is 64 x 128 pixels)
	double margin = 0.05;	 ///< boxes grow by this fraction of their size on each side
	int max_age_frames = 10; ///< a carried box is forgotten after this many frames without a detection
	PriorLabelRule rule = PriorLabelRule::Judged;
	double memory_chi2 = 2.0; ///< Weighted: the memory's gate in a person box (memory.chi2 elsewhere)
	PriorDetector detector = PriorDetector::Hog;
	std::string model_path;			 ///< Onnx: the file (read by the daemon at start)
	PriorModelSpec model_spec;		 ///< Onnx: how to run it and read its output
	std::shared_ptr<const PriorModel> model; ///< Onnx: loaded at start; shared by the workers
	/// The potentially dynamic category: the share of an object's decided points that must be dynamic
	/// for all of them to be (vote_potentially_dynamic).
	double object_vote = 0.5;
};

/// One region of the prior, in the left image's pixels.
struct PriorRegion {
	cv::Rect2f box;
	float score = 0;
	PriorCategory category = PriorCategory::Dynamic;
	int age_frames = 0; ///< frames since the detector saw it (0: detected in this frame)
	int class_id = -1;  ///< the model's class (prior_model.hpp); -1: HOG's person
	/// Segmentation: CV_8U, the box's size, non-zero where the object is (it moves with the box); empty:
	/// the whole box.
	cv::Mat mask;
};

/// Whether `point` lies on the region: inside its box and, with a mask, on the object.
bool region_contains(const PriorRegion &region, cv::Point2f point);

/// People in a grey image: HOG + linear SVM over a scale pyramid, overlapping windows grouped, each kept when
/// its margin reaches `min_score`, grown by `margin`. Nothing for an empty image.
std::vector<PriorRegion> detect_people(const cv::Mat &grey, const PersonPriorParams &params);

/// Frame n-1's regions carried to frame n: each box moves by the median displacement of the matches that
/// start inside it (unmoved when none do) and ages by one; boxes older than `max_age_frames` are dropped.
std::vector<PriorRegion> carry_regions(std::span<const PriorRegion> regions, std::span<const cv::Point2f> from,
				       std::span<const cv::Point2f> to, int max_age_frames);

/// Per point: 1 where it lies in a region of the dynamic category.
std::vector<uint8_t> in_dynamic_category(std::span<const cv::Point2f> points, std::span<const PriorRegion> regions);

/// Seed 001 on the potentially dynamic category (chairs): its points are judged like any other, then "the
/// number of dynamic feature points in the category" decides for the object. Where at least `min_share` of
/// the decided points of one such region (and at least 2) are dynamic, the object has been moved and all its
/// points become dynamic; returns how many labels changed.
int vote_potentially_dynamic(std::span<const cv::Point2f> points, std::span<const PriorRegion> regions,
			     std::span<PointLabel> labels, double min_share);

} // namespace stereod::vision
