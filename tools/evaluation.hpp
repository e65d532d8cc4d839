#pragma once
// Scoring labelled points against per-pixel dynamic masks (ground truth): precision, recall and F1 of the
// `dynamic` label, and the static-point error rate. Pure: masks and results in, numbers out.
#include <cstdint>
#include <string>

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

/// A table row: "name frames points P R F1 static-error uncertain coverage".
std::string format_score_row(const std::string &name, const LabelScore &score);
std::string score_table_header();

} // namespace stereod::tools
