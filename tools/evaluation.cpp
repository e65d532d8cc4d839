#include "tools/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

namespace stereod::tools {
namespace {

double ratio(uint64_t num, uint64_t den)
{
	return den == 0 ? 0.0 : static_cast<double>(num) / static_cast<double>(den);
}

} // namespace

LabelScore &LabelScore::operator+=(const LabelScore &o)
{
	frames += o.frames;
	dynamic_true += o.dynamic_true;
	dynamic_false += o.dynamic_false;
	static_true += o.static_true;
	static_false += o.static_false;
	uncertain_on_mover += o.uncertain_on_mover;
	uncertain_on_scene += o.uncertain_on_scene;
	mover_coverage_sum += o.mover_coverage_sum;
	return *this;
}

void LabelScore::add(PointLabel label, bool on_mover)
{
	switch (label) {
	case PointLabel::Dynamic:
		++(on_mover ? dynamic_true : dynamic_false);
		break;
	case PointLabel::Static:
		++(on_mover ? static_false : static_true);
		break;
	case PointLabel::Uncertain:
		++(on_mover ? uncertain_on_mover : uncertain_on_scene);
		break;
	}
}

double LabelScore::precision() const
{
	return ratio(dynamic_true, dynamic_true + dynamic_false);
}

double LabelScore::recall() const
{
	return ratio(dynamic_true, dynamic_true + static_false);
}

double LabelScore::f1() const
{
	const double p = precision(), r = recall();
	return p + r > 0 ? 2 * p * r / (p + r) : 0.0;
}

double LabelScore::static_error_rate() const
{
	return ratio(static_false, static_true + static_false);
}

double LabelScore::uncertain_rate() const
{
	const uint64_t uncertain = uncertain_on_mover + uncertain_on_scene;
	return ratio(uncertain, uncertain + dynamic_true + dynamic_false + static_true + static_false);
}

double LabelScore::mean_coverage() const
{
	return frames == 0 ? 0.0 : mover_coverage_sum / static_cast<double>(frames);
}

PriorRegionScore &PriorRegionScore::operator+=(const PriorRegionScore &other)
{
	detected += other.detected;
	detected_on_mover += other.detected_on_mover;
	carried += other.carried;
	carried_on_mover += other.carried_on_mover;
	return *this;
}

PriorRegionScore score_prior_regions(const FrameResult &result, const cv::Mat &mask, double min_fraction)
{
	PriorRegionScore score;
	const cv::Rect frame(0, 0, mask.cols, mask.rows);
	for (const PersonRegion &region : result.people) {
		const cv::Rect box =
			cv::Rect(cv::Point(static_cast<int>(region.box_px[0]), static_cast<int>(region.box_px[1])),
				 cv::Point(static_cast<int>(region.box_px[2]), static_cast<int>(region.box_px[3]))) &
			frame;
		const bool on_mover = box.area() > 0 && static_cast<double>(cv::countNonZero(mask(box))) >=
								min_fraction * static_cast<double>(box.area());
		if (region.age_frames == 0) {
			++score.detected;
			score.detected_on_mover += on_mover;
		} else {
			++score.carried;
			score.carried_on_mover += on_mover;
		}
	}
	return score;
}

LabelScore score_frame(const FrameResult &result, const cv::Mat &mask, int border_px)
{
	CV_Assert(mask.type() == CV_8UC1);
	LabelScore score;
	score.frames = 1;
	score.mover_coverage_sum = static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(mask.total());
	cv::Mat ambiguous;
	if (border_px > 0) {
		cv::Mat grown, shrunk;
		const cv::Mat kernel =
			cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * border_px + 1, 2 * border_px + 1));
		cv::dilate(mask, grown, kernel);
		cv::erode(mask, shrunk, kernel);
		ambiguous = grown != shrunk;
	}
	for (const auto &point : result.points) {
		const int x = cvRound(point.u), y = cvRound(point.v);
		if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows)
			continue;
		if (!ambiguous.empty() && ambiguous.at<uint8_t>(y, x))
			continue;
		score.add(point.label, mask.at<uint8_t>(y, x) != 0);
	}
	return score;
}

double MoverCounts::recall() const
{
	return ratio(dynamic, dynamic + static_);
}

void count_per_mover(const FrameResult &result, const cv::Mat &mask, std::map<int, MoverCounts> &counts)
{
	CV_Assert(mask.type() == CV_8UC1);
	for (const auto &point : result.points) {
		const int x = cvRound(point.u), y = cvRound(point.v);
		if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows)
			continue;
		const int id = mask.at<uint8_t>(y, x);
		if (id == 0)
			continue;
		MoverCounts &c = counts[id];
		switch (point.label) {
		case PointLabel::Dynamic:
			++c.dynamic;
			break;
		case PointLabel::Static:
			++c.static_;
			break;
		case PointLabel::Uncertain:
			++c.uncertain;
			break;
		}
	}
}

std::string label_errors_header()
{
	return "seq,u,v,label,mover,outline_px,z_m,z_true_m";
}

void write_label_errors(std::ostream &out, uint64_t seq, const FrameResult &result, const cv::Mat &mask,
			const cv::Mat &depth_mm)
{
	CV_Assert(mask.type() == CV_8UC1);
	// Distance to the outline from either side: inside a mover, to the nearest scene pixel; outside, to the
	// nearest mover pixel.
	cv::Mat inside, outside;
	cv::distanceTransform(mask != 0, inside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
	cv::distanceTransform(mask == 0, outside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
	for (const auto &point : result.points) {
		const int x = cvRound(point.u), y = cvRound(point.v);
		if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows)
			continue;
		const int mover = mask.at<uint8_t>(y, x);
		const bool wrong = (point.label == PointLabel::Dynamic && mover == 0) ||
				   (point.label == PointLabel::Static && mover != 0);
		if (!wrong)
			continue;
		const float outline = mover != 0 ? inside.at<float>(y, x) : outside.at<float>(y, x);
		out << seq << ',' << point.u << ',' << point.v << ',' << to_string(point.label) << ',' << mover << ','
		    << outline << ',';
		if (point.xyz_m)
			out << (*point.xyz_m)[2];
		out << ',';
		if (!depth_mm.empty() && depth_mm.at<uint16_t>(y, x) != 0)
			out << depth_mm.at<uint16_t>(y, x) * 1e-3;
		out << '\n';
	}
}

std::string score_table_header()
{
	return "| scene | frames | decided points | dynamic precision | dynamic recall | dynamic F1 | static error "
	       "rate | uncertain | mover coverage |\n|---|---|---|---|---|---|---|---|---|";
}

std::string format_score_row(const std::string &name, const LabelScore &s)
{
	char line[512];
	std::snprintf(
		line, sizeof(line), "| %s | %llu | %llu | %.3f | %.3f | %.3f | %.4f | %.3f | %.1f%% |", name.c_str(),
		static_cast<unsigned long long>(s.frames),
		static_cast<unsigned long long>(s.dynamic_true + s.dynamic_false + s.static_true + s.static_false),
		s.precision(), s.recall(), s.f1(), s.static_error_rate(), s.uncertain_rate(),
		100.0 * s.mean_coverage());
	return line;
}

DepthScore &DepthScore::operator+=(const DepthScore &other)
{
	relative_errors.insert(relative_errors.end(), other.relative_errors.begin(), other.relative_errors.end());
	points += other.points;
	with_depth += other.with_depth;
	return *this;
}

double median(std::vector<double> values)
{
	if (values.empty())
		return std::nan("");
	const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
	std::nth_element(values.begin(), mid, values.end());
	return *mid;
}

double DepthScore::median() const
{
	return relative_errors.empty() ? 0 : tools::median(relative_errors);
}

double DepthScore::fraction_within(double relative) const
{
	if (relative_errors.empty())
		return 0;
	const auto n =
		std::count_if(relative_errors.begin(), relative_errors.end(), [&](double e) { return e <= relative; });
	return static_cast<double>(n) / static_cast<double>(relative_errors.size());
}

DepthScore score_depth(const FrameResult &result, const cv::Mat &depth_mm)
{
	DepthScore score;
	for (const auto &point : result.points) {
		++score.points;
		if (!point.xyz_m)
			continue;
		++score.with_depth;
		const int x = static_cast<int>(std::lround(point.u));
		const int y = static_cast<int>(std::lround(point.v));
		if (x < 0 || y < 0 || x >= depth_mm.cols || y >= depth_mm.rows)
			continue;
		const uint16_t truth = depth_mm.at<uint16_t>(y, x);
		if (truth == 0)
			continue;
		const double z_true = truth * 1e-3;
		score.relative_errors.push_back(std::abs(static_cast<double>((*point.xyz_m)[2]) - z_true) / z_true);
	}
	return score;
}

} // namespace stereod::tools
