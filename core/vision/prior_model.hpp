#pragma once
// A user-supplied ONNX model for seed 001's semantic prior, run through OpenCV's dnn module (no other runtime):
// a detector (YOLO-family output: boxes and class scores) or a semantic segmentation network (per-pixel
// class scores, as seed 001's PSPNet). A configurable map says which of the model's classes are the dynamic
// category (people, animals) and which the potentially dynamic one (chairs, monitors); other classes are
// ignored. HOG (person_prior.hpp) stays the default: it needs no weights.
//
// The model is loaded once, at start, from bytes the caller read (core does no I/O); a model that cannot be
// parsed, or whose output does not have the layout the configuration names, is refused there with the
// reason, not at the first frame.
#include <cstdint>
#include <mutex>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include "core/vision/person_prior.hpp"

namespace stereod::vision {

/// "0:dynamic,56:potentially_dynamic" -> the map; throws std::invalid_argument naming the bad item.
std::vector<ModelClass> parse_class_map(std::string_view text);
std::string format_class_map(std::span<const ModelClass> classes);

/// Where the image sits in the network's input: scaled by `scale` and padded right and below.
struct Letterbox {
	double scale = 1;
	cv::Size content; ///< the scaled image's size in input pixels
};
Letterbox letterbox_for(cv::Size image, cv::Size input);

/// A detector's output (one image) -> regions in image pixels: candidates whose score reaches
/// min_confidence and whose class is in the map, non-maximum suppression per class, boxes clipped to the
/// image and grown by `margin` of their size a side. Throws std::runtime_error when `output`'s shape does not
/// fit `spec.layout`.
std::vector<PriorRegion> decode_detections(const cv::Mat &output, const PriorModelSpec &spec, const Letterbox &box,
					   cv::Size image, double margin);

/// A segmentation network's output -> one region per connected area of a mapped class (at least
/// min_region_px image pixels): its box, and its mask so that only points on the object count.
std::vector<PriorRegion> decode_segmentation(const cv::Mat &output, const PriorModelSpec &spec, const Letterbox &box,
					     cv::Size image);

class PriorModelError : public std::runtime_error
{
public:
	using std::runtime_error::runtime_error;
};

/// A loaded model. Safe to share between workers: runs are serialised (a dnn::Net is not re-entrant), which
/// costs nothing measurable at the prior's every-k-th-frame rate.
class PriorModel
{
public:
	/// Parses the ONNX bytes and runs the network once on a blank image to check its output against
	/// `spec` (layout, class ids in range). Throws PriorModelError with the reason.
	PriorModel(std::span<const char> onnx, PriorModelSpec spec);

	/// Regions in a BGR or grey 8-bit image. Nothing for an empty image.
	std::vector<PriorRegion> detect(const cv::Mat &image, double margin) const;

	const PriorModelSpec &spec() const { return spec_; }
	int output_classes() const { return output_classes_; }

private:
	cv::Mat run(const cv::Mat &image, Letterbox &box) const;

	PriorModelSpec spec_;
	int output_classes_ = 0;
	mutable std::mutex mutex_;
	mutable cv::dnn::Net net_;
};

} // namespace stereod::vision
