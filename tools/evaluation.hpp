#pragma once
// Scoring labelled points against per-pixel dynamic masks (ground truth): precision, recall and F1 of the
// `dynamic` label, and the static-point error rate. Pure: masks and results in, numbers out.
#include <cstdint>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/result.hpp"

namespace stereod::tools {

struct LabelScore {
	uint64_t frames = 0;
	uint64_t dynamic_true = 0;  ///< labelled dynamic, on a mover
	uint64_t dynamic_false = 0; ///< labelled dynamic, on the static scene
	uint64_t static_true = 0;   ///< labelled static, on the static scene
	uint64_t static_false = 0;  ///< labelled static, on a mover (a missed dynamic point)
	uint64_t uncertain_on_mover = 0;
	uint64_t uncertain_on_scene = 0;
	double mover_coverage_sum = 0; ///< sum over frames of the fraction of pixels on movers

	LabelScore &operator+=(const LabelScore &other);
	/// Counts one point with `label`, lying on a mover or on the static scene.
	void add(PointLabel label, bool on_mover);
	[[nodiscard]] double precision() const;
	[[nodiscard]] double recall() const;
	[[nodiscard]] double f1() const;
	/// Points labelled static that lie on a mover, over all points labelled static.
	[[nodiscard]] double static_error_rate() const;
	/// Points left uncertain over all points.
	[[nodiscard]] double uncertain_rate() const;
	[[nodiscard]] double mean_coverage() const;
};

/// Scores one frame's points; `mask` is CV_8UC1, non-zero on movers. Points within `border_px` of a mask
/// edge are skipped (their label is ambiguous: the descriptor patch straddles mover and scene).
LabelScore score_frame(const FrameResult &result, const cv::Mat &mask, int border_px = 0);

/// The median (the upper one of an even count); NaN when empty.
double median(std::vector<double> values);

/// Labels of the points on each mover, by the mover's id in the mask (the sim writes ids 1..N): shows which
/// mover a method misses (recall per mover = dynamic / (dynamic + static)).
struct MoverCounts {
	uint64_t dynamic = 0;
	uint64_t static_ = 0;
	uint64_t uncertain = 0;
	[[nodiscard]] double recall() const;
};
void count_per_mover(const FrameResult &result, const cv::Mat &mask, std::map<int, MoverCounts> &counts);

/// Measured depth (points' xyz_m) against the true depth image (16-bit millimetres, 0 = unknown).
struct DepthScore {
	std::vector<double> relative_errors; ///< |z - z_true| / z_true per point with both
	uint64_t points = 0;		     ///< points in the frames scored
	uint64_t with_depth = 0;	     ///< of those, with xyz_m
	DepthScore &operator+=(const DepthScore &other);
	[[nodiscard]] double median() const;
	[[nodiscard]] double fraction_within(double relative) const;
};
DepthScore score_depth(const FrameResult &result, const cv::Mat &depth_mm);

/// The person prior's regions against the movers: a region detected in this frame (age 0) is on a mover when
/// at least `min_fraction` of its pixels are; carried regions are counted apart.
struct PriorRegionScore {
	uint64_t detected = 0;
	uint64_t detected_on_mover = 0;
	uint64_t carried = 0;
	uint64_t carried_on_mover = 0;
	PriorRegionScore &operator+=(const PriorRegionScore &other);
};
PriorRegionScore score_prior_regions(const FrameResult &result, const cv::Mat &mask, double min_fraction = 0.1);

/// Every wrongly labelled point of one frame as CSV lines "seq,u,v,label,mover,outline_px,z_m,z_true_m":
/// `mover` is the mask id under the point (0 = the static scene), `outline_px` its distance to the nearest
/// mover outline, `z_m` / `z_true_m` the measured and true depth (empty when unknown). `depth_mm` may be
/// empty. For finding where a method errs (near outlines, far away, without depth) rather than only how often.
void write_label_errors(std::ostream &out, uint64_t seq, const FrameResult &result, const cv::Mat &mask,
			const cv::Mat &depth_mm);
std::string label_errors_header();

/// A table row: "name frames points P R F1 static-error uncertain coverage".
std::string format_score_row(const std::string &name, const LabelScore &score);
std::string score_table_header();

} // namespace stereod::tools
