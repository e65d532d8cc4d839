#include "core/vision/matching.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>

#include <opencv2/video/tracking.hpp>

#include <opencv2/features2d.hpp>

#include "core/vision/structure_tensor.hpp"

namespace stereod::vision {
namespace {

constexpr int kUnset = -1;

/// Hamming distances of one descriptor to a block of descriptors. Two builds of the same loop: one with
/// the popcnt instruction for CPUs that have it, a portable one otherwise, chosen once at run time, so one
/// binary runs on any x86-64 or ARM board. (Not an ifunc: sanitizer runtimes cannot run ifunc resolvers.)
template <typename Word>
inline void hamming_rows_generic(const Word *query, const Word *train, int train_rows, int words, int *out)
{
	for (int j = 0; j < train_rows; ++j) {
		const Word *t = train + static_cast<ptrdiff_t>(j) * words;
		int d = 0;
		for (int w = 0; w < words; ++w)
			d += std::popcount(query[w] ^ t[w]);
		out[j] = d;
	}
}

void hamming_rows_portable(const uint64_t *query, const uint64_t *train, int train_rows, int words, int *out)
{
	hamming_rows_generic(query, train, train_rows, words, out);
}

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("popcnt"))) void hamming_rows_popcnt(const uint64_t *query, const uint64_t *train, int train_rows,
							   int words, int *out)
{
	hamming_rows_generic(query, train, train_rows, words, out);
}
#endif

using HammingRows = void (*)(const uint64_t *, const uint64_t *, int, int, int *);

HammingRows select_hamming_rows()
{
#if defined(__x86_64__) && defined(__GNUC__)
	if (__builtin_cpu_supports("popcnt"))
		return hamming_rows_popcnt;
#endif
	return hamming_rows_portable;
}

void hamming_rows(const uint64_t *query, const uint64_t *train, int train_rows, int words, int *out)
{
	static const HammingRows chosen = select_hamming_rows();
	chosen(query, train, train_rows, words, out);
}

/// Best and second-best per row and best per column over the candidate pairs a caller visits, then the ratio
/// test, max distance and cross check: the filtering shared by brute-force (binary) and guided matching.
template <typename Distance>
class CandidateTable
{
public:
	CandidateTable(int n_prev, int n_cur)
		: rows_(static_cast<size_t>(n_prev)), col_best_(static_cast<size_t>(n_cur), kNone),
		  col_arg_(static_cast<size_t>(n_cur), kUnset)
	{
	}
	void add(int i, int j, Distance d) { add_to(rows_[static_cast<size_t>(i)], i, j, d); }
	/// Row i against every column: the brute-force case, with the row's state held across the loop.
	void add_row(int i, const Distance *distances, int n)
	{
		Row &r = rows_[static_cast<size_t>(i)];
		for (int j = 0; j < n; ++j)
			add_to(r, i, j, distances[j]);
	}
	[[nodiscard]] std::vector<Match> matches(const MatchParams &params, Distance max_distance) const
	{
		std::vector<Match> out;
		for (size_t i = 0; i < rows_.size(); ++i) {
			const Row &r = rows_[i];
			if (r.arg == kUnset || r.best > max_distance)
				continue;
			if (r.second != kNone &&
			    static_cast<float>(r.best) > params.ratio * static_cast<float>(r.second))
				continue;
			if (params.cross_check && col_arg_[static_cast<size_t>(r.arg)] != static_cast<int>(i))
				continue;
			out.push_back({static_cast<int>(i), r.arg, static_cast<float>(r.best)});
		}
		return out;
	}

private:
	struct Row;
	void add_to(Row &r, int i, int j, Distance d)
	{
		if (d < r.best) {
			r.second = r.best;
			r.best = d;
			r.arg = j;
		} else if (d < r.second) {
			r.second = d;
		}
		if (d < col_best_[static_cast<size_t>(j)]) {
			col_best_[static_cast<size_t>(j)] = d;
			col_arg_[static_cast<size_t>(j)] = i;
		}
	}
	static constexpr Distance kNone = std::numeric_limits<Distance>::max();
	struct Row {
		Distance best = kNone, second = kNone;
		int arg = kUnset;
	};
	std::vector<Row> rows_;
	std::vector<Distance> col_best_;
	std::vector<int> col_arg_;
};

/// Brute force in one pass over the distance matrix: each query row's two nearest (for the ratio test) and
/// each train row's nearest (for the cross check) come from the same distances, computed once.
std::vector<Match> match_binary(const cv::Mat &prev, const cv::Mat &cur, const MatchParams &params)
{
	const int words = prev.cols / 8;
	// Rows are read as 64-bit words (the caller checked cols % 8 == 0); OpenCV's row starts are 8-byte
	// aligned for such widths, so only a non-continuous view needs copying.
	const cv::Mat prev_words = prev.isContinuous() ? prev : prev.clone();
	const cv::Mat cur_words = cur.isContinuous() ? cur : cur.clone();
	const int n_prev = prev.rows, n_cur = cur.rows;
	std::vector<int> distances(static_cast<size_t>(n_cur));
	CandidateTable<int> table(n_prev, n_cur);
	for (int i = 0; i < n_prev; ++i) {
		hamming_rows(prev_words.ptr<uint64_t>(i), cur_words.ptr<uint64_t>(0), n_cur, words, distances.data());
		table.add_row(i, distances.data(), n_cur);
	}
	return table.matches(params, params.max_distance);
}

/// Float descriptors (SURF) through OpenCV's matcher.
std::vector<Match> match_float(const cv::Mat &prev, const cv::Mat &cur, const MatchParams &params, int norm)
{
	cv::BFMatcher matcher(norm, false);
	std::vector<std::vector<cv::DMatch>> forward;
	matcher.knnMatch(prev, cur, forward, 2);
	std::vector<int> backward_best;
	if (params.cross_check) {
		std::vector<cv::DMatch> backward;
		matcher.match(cur, prev, backward);
		backward_best.assign(static_cast<size_t>(cur.rows), kUnset);
		for (const auto &m : backward)
			backward_best[static_cast<size_t>(m.queryIdx)] = m.trainIdx;
	}
	std::vector<Match> matches;
	for (const auto &candidates : forward) {
		if (candidates.empty())
			continue;
		const cv::DMatch &best = candidates[0];
		// max_distance is in Hamming bits; float descriptors rely on the ratio test and cross check.
		if (candidates.size() > 1 && best.distance > params.ratio * candidates[1].distance)
			continue;
		if (params.cross_check && backward_best[static_cast<size_t>(best.trainIdx)] != best.queryIdx)
			continue;
		matches.push_back({best.queryIdx, best.trainIdx, best.distance});
	}
	return matches;
}

/// Keypoints of one frame binned on a square grid of the search radius, so the candidates near a point are
/// in the 3 x 3 cells around it.
class KeypointGrid
{
public:
	KeypointGrid(const std::vector<cv::KeyPoint> &keypoints, float cell) : cell_(cell)
	{
		std::vector<std::pair<int64_t, int>> keyed(keypoints.size());
		for (size_t j = 0; j < keypoints.size(); ++j)
			keyed[j] = {key(cell_of(keypoints[j].pt.x), cell_of(keypoints[j].pt.y)), static_cast<int>(j)};
		std::sort(keyed.begin(), keyed.end());
		sorted_keys_.reserve(keyed.size());
		order_.reserve(keyed.size());
		for (const auto &[k, j] : keyed) {
			sorted_keys_.push_back(k);
			order_.push_back(j);
		}
	}
	/// Calls visit(j) for every keypoint in the cells around `at` (a superset of those within one cell).
	template <typename Visit>
	void around(cv::Point2f at, Visit &&visit) const
	{
		const int64_t cx = cell_of(at.x), cy = cell_of(at.y);
		for (int64_t y = cy - 1; y <= cy + 1; ++y) {
			for (int64_t x = cx - 1; x <= cx + 1; ++x) {
				const auto [lo, hi] =
					std::equal_range(sorted_keys_.begin(), sorted_keys_.end(), key(x, y));
				for (auto it = lo; it != hi; ++it)
					visit(order_[static_cast<size_t>(it - sorted_keys_.begin())]);
			}
		}
	}

private:
	[[nodiscard]] int64_t cell_of(float v) const { return static_cast<int64_t>(std::floor(v / cell_)); }
	static int64_t key(int64_t x, int64_t y) { return (y << 32) + x; }
	float cell_;
	std::vector<int64_t> sorted_keys_; ///< cell keys in ascending order
	std::vector<int> order_;	   ///< the keypoint index of each sorted key
};

constexpr int kRescueLevels = 3; ///< pyramid levels of the rescue's Lucas-Kanade

/// Descriptors compared by Hamming distance on 64-bit words (ORB); anything else goes by its float norm.
bool binary_descriptors(const FrameFeatures &prev, const FrameFeatures &cur)
{
	return cur.norm_type == cv::NORM_HAMMING && prev.descriptors.type() == CV_8U &&
	       prev.descriptors.cols % 8 == 0 && prev.descriptors.cols == cur.descriptors.cols;
}

/// Row i of `prev_d` against row j of `cur_d`: Hamming bits when `binary` (both continuous, see
/// binary_descriptors), else their `norm_type` distance.
float descriptor_distance(const cv::Mat &prev_d, int i, const cv::Mat &cur_d, int j, bool binary, int norm_type)
{
	if (binary) {
		int bits = 0;
		hamming_rows(prev_d.ptr<uint64_t>(i), cur_d.ptr<uint64_t>(j), 1, prev_d.cols / 8, &bits);
		return static_cast<float>(bits);
	}
	return static_cast<float>(cv::norm(prev_d.row(i), cur_d.row(j), norm_type));
}

/// Rows read as 64-bit words need a continuous matrix; extracted descriptors are, so this rarely copies.
cv::Mat continuous(const cv::Mat &m)
{
	return m.isContinuous() ? m : m.clone();
}

/// A frame's Lucas-Kanade pyramid: the extract stage's, else one built into `scratch`.
const std::vector<cv::Mat> &pyramid_of(const FrameFeatures &features, std::vector<cv::Mat> &scratch,
				       const MatchParams &params)
{
	if (!features.grey_pyramid.empty())
		return features.grey_pyramid;
	scratch = lk_pyramid(features.grey, params);
	return scratch;
}

/// Lucas-Kanade as the rescue and the followed points use it, on the frames' pyramids (kRescueLevels levels,
/// the rescue's window): each point of `from` in `from_pyramid` to where it lies in `to_pyramid`, from the
/// guess in `to` (overwritten); `status` 0 where it was lost.
void follow_by_lk(const std::vector<cv::Mat> &from_pyramid, const std::vector<cv::Mat> &to_pyramid,
		  const std::vector<cv::Point2f> &from, std::vector<cv::Point2f> &to, std::vector<uchar> &status,
		  const MatchParams &params, std::vector<float> &error)
{
	cv::calcOpticalFlowPyrLK(from_pyramid, to_pyramid, from, to, status, error,
				 cv::Size(params.rescue_window_px, params.rescue_window_px), kRescueLevels - 1,
				 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 10, 0.03),
				 cv::OPTFLOW_USE_INITIAL_FLOW);
}

void follow_by_lk(const std::vector<cv::Mat> &from_pyramid, const std::vector<cv::Mat> &to_pyramid,
		  const std::vector<cv::Point2f> &from, std::vector<cv::Point2f> &to, std::vector<uchar> &status,
		  const MatchParams &params)
{
	std::vector<float> error;
	follow_by_lk(from_pyramid, to_pyramid, from, to, status, params, error);
}

/// Across which way the window (side `window`) around `at` is one-sided: the unit eigenvector of its structure
/// tensor's larger eigenvalue when the smaller is under `ratio` of it (an edge, a streak), else (0, 0). From
/// `derivatives`, a Lucas-Kanade pyramid's level (CV_16SC2).
cv::Point2f edge_across_in(const cv::Mat &derivatives, cv::Point2f at, int window, double ratio)
{
	const int half = window / 2;
	const int x0 = static_cast<int>(std::lround(at.x)), y0 = static_cast<int>(std::lround(at.y));
	double sxx = 0, sxy = 0, syy = 0;
	for (int y = std::max(y0 - half, 0); y <= std::min(y0 + half, derivatives.rows - 1); ++y) {
		const auto *row = derivatives.ptr<cv::Vec2s>(y);
		for (int x = std::max(x0 - half, 0); x <= std::min(x0 + half, derivatives.cols - 1); ++x) {
			const double gx = row[x][0], gy = row[x][1];
			sxx += gx * gx;
			sxy += gx * gy;
			syy += gy * gy;
		}
	}
	const std::optional<double> angle = edge_angle(sxx, sxy, syy, ratio);
	if (!angle)
		return {0, 0};
	return {static_cast<float>(std::cos(*angle)), static_cast<float>(std::sin(*angle))};
}

} // namespace

cv::Point2f edge_across(const FrameFeatures &features, cv::Point2f at, const MatchParams &params, double ratio)
{
	if (ratio <= 0 || features.grey_pyramid.size() < 2)
		return {0, 0};
	return edge_across_in(features.grey_pyramid[1], at, params.rescue_window_px, ratio);
}

std::vector<Match> match_features_guided(const FrameFeatures &prev, const FrameFeatures &cur,
					 std::span<const cv::Point2f> predicted, const MatchParams &params)
{
	if (prev.descriptors.empty() || cur.descriptors.empty() || params.search_radius_px <= 0 ||
	    predicted.size() != prev.keypoints.size() || prev.descriptors.cols != cur.descriptors.cols ||
	    prev.descriptors.type() != cur.descriptors.type())
		return match_features(prev, cur, params);
	const float radius = params.search_radius_px;
	const float radius2 = radius * radius;
	const KeypointGrid grid(cur.keypoints, radius);
	CandidateTable<float> table(prev.descriptors.rows, cur.descriptors.rows);
	const bool binary = binary_descriptors(prev, cur);
	const cv::Mat prev_d = continuous(prev.descriptors);
	const cv::Mat cur_d = continuous(cur.descriptors);
	for (int i = 0; i < prev_d.rows; ++i) {
		const cv::Point2f at = predicted[static_cast<size_t>(i)];
		if (!std::isfinite(at.x) || !std::isfinite(at.y))
			continue;
		grid.around(at, [&](int j) {
			const cv::Point2f offset = cur.keypoints[static_cast<size_t>(j)].pt - at;
			if (offset.dot(offset) > radius2)
				return;
			table.add(i, j, descriptor_distance(prev_d, i, cur_d, j, binary, cur.norm_type));
		});
	}
	// max_distance is in Hamming bits; float descriptors rely on the ratio test and cross check.
	return table.matches(params,
			     binary ? static_cast<float>(params.max_distance) : std::numeric_limits<float>::max());
}

std::vector<Match> match_features(const FrameFeatures &prev, const FrameFeatures &cur, const MatchParams &params)
{
	if (prev.descriptors.empty() || cur.descriptors.empty())
		return {};
	if (binary_descriptors(prev, cur))
		return match_binary(prev.descriptors, cur.descriptors, params);
	return match_float(prev.descriptors, cur.descriptors, params, cur.norm_type);
}

std::vector<cv::Mat> lk_pyramid(const cv::Mat &grey, const MatchParams &params)
{
	// Bordered for the larger of the two windows that use it: the rescue's and the sub-pixel step's.
	const int border = std::max(params.rescue_window_px, params.subpixel_window_px);
	std::vector<cv::Mat> pyramid;
	if (!grey.empty())
		cv::buildOpticalFlowPyramid(grey, pyramid, cv::Size(border, border), kRescueLevels - 1, true);
	return pyramid;
}

int rescue_matches(const FrameFeatures &prev, const FrameFeatures &cur, std::span<const cv::Point2f> predicted,
		   std::vector<Match> &matches, const MatchParams &params)
{
	if (prev.grey.empty() || cur.grey.empty() || prev.grey.size() != cur.grey.size() || prev.keypoints.empty() ||
	    cur.keypoints.empty() || prev.descriptors.rows != static_cast<int>(prev.keypoints.size()) ||
	    cur.descriptors.rows != static_cast<int>(cur.keypoints.size()) ||
	    prev.descriptors.cols != cur.descriptors.cols || prev.descriptors.type() != cur.descriptors.type())
		return 0;
	std::vector<uint8_t> prev_matched(prev.keypoints.size(), 0), cur_matched(cur.keypoints.size(), 0);
	for (const Match &m : matches) {
		prev_matched[static_cast<size_t>(m.prev)] = 1;
		cur_matched[static_cast<size_t>(m.cur)] = 1;
	}
	// Only points with an unmatched keypoint near their predicted position can be joined: the rest are not
	// followed at all (Lucas-Kanade is the cost here, about 30 us a point both ways).
	const float reach = std::max(params.rescue_reach_px, params.rescue_radius_px);
	const KeypointGrid grid(cur.keypoints, reach); // its cells hold both the reach and the radius

	std::vector<int> lost;
	std::vector<cv::Point2f> from, to;
	const bool use_prediction = predicted.size() == prev.keypoints.size();
	for (size_t i = 0; i < prev.keypoints.size(); ++i) {
		if (prev_matched[i] != 0)
			continue;
		const cv::Point2f start = use_prediction ? predicted[i] : prev.keypoints[i].pt;
		if (!std::isfinite(start.x) || !std::isfinite(start.y))
			continue;
		bool free_nearby = false;
		grid.around(start, [&](int j) {
			const cv::Point2f offset = cur.keypoints[static_cast<size_t>(j)].pt - start;
			free_nearby = free_nearby ||
				      (cur_matched[static_cast<size_t>(j)] == 0 && offset.dot(offset) <= reach * reach);
		});
		if (!free_nearby)
			continue;
		lost.push_back(static_cast<int>(i));
		from.push_back(prev.keypoints[i].pt);
		to.push_back(start);
	}
	if (lost.empty())
		return 0;
	std::vector<cv::Mat> prev_scratch, cur_scratch;
	const std::vector<cv::Mat> &prev_pyramid = pyramid_of(prev, prev_scratch, params);
	const std::vector<cv::Mat> &cur_pyramid = pyramid_of(cur, cur_scratch, params);
	std::vector<uchar> status;
	follow_by_lk(prev_pyramid, cur_pyramid, from, to, status, params);

	// The nearest unmatched keypoint where each point landed.
	const float radius = params.rescue_radius_px;
	struct Candidate {
		float distance2;
		int prev, cur;
		float descriptor_distance;
	};
	std::vector<Candidate> candidates;
	std::vector<cv::Point2f> landed, back;
	for (size_t k = 0; k < lost.size(); ++k) {
		if (status[k] == 0 || !std::isfinite(to[k].x) || !std::isfinite(to[k].y))
			continue;
		int best = -1;
		float best2 = radius * radius;
		grid.around(to[k], [&](int j) {
			if (cur_matched[static_cast<size_t>(j)] != 0)
				return;
			const cv::Point2f offset = cur.keypoints[static_cast<size_t>(j)].pt - to[k];
			const float d2 = offset.dot(offset);
			if (d2 <= best2) {
				best2 = d2;
				best = j;
			}
		});
		if (best < 0)
			continue;
		candidates.push_back({best2, lost[k], best, 0});
		landed.push_back(to[k]);
		back.push_back(from[k]);
	}
	if (candidates.empty())
		return 0;
	// Followed back from where they landed, they must come home: a point that slid along an edge or onto
	// another surface does not.
	std::vector<cv::Point2f> home = back;
	follow_by_lk(cur_pyramid, prev_pyramid, landed, back, status, params);
	const bool binary = binary_descriptors(prev, cur);
	const cv::Mat prev_d = continuous(prev.descriptors);
	const cv::Mat cur_d = continuous(cur.descriptors);
	const float back2 = params.rescue_back_px * params.rescue_back_px;
	size_t kept = 0;
	for (size_t k = 0; k < candidates.size(); ++k) {
		const cv::Point2f round_trip = back[k] - home[k];
		if (status[k] == 0 || !(round_trip.dot(round_trip) <= back2))
			continue;
		Candidate c = candidates[k];
		c.descriptor_distance = descriptor_distance(prev_d, c.prev, cur_d, c.cur, binary, cur.norm_type);
		// max_distance is in Hamming bits; float descriptors have no such scale.
		if (binary && c.descriptor_distance > static_cast<float>(params.rescue_max_distance))
			continue;
		candidates[kept++] = c;
	}
	candidates.resize(kept);
	std::sort(candidates.begin(), candidates.end(),
		  [](const Candidate &a, const Candidate &b) { return a.distance2 < b.distance2; });
	int added = 0;
	for (const Candidate &c : candidates) {
		if (cur_matched[static_cast<size_t>(c.cur)] != 0)
			continue;
		cur_matched[static_cast<size_t>(c.cur)] = 1;
		matches.push_back({c.prev, c.cur, c.descriptor_distance});
		++added;
	}
	return added;
}

std::vector<FollowedPoint> follow_unmatched(const FrameFeatures &prev, const FrameFeatures &cur,
					    std::span<const cv::Point2f> predicted, std::span<const Match> matches,
					    const MatchParams &params, double aperture_ratio,
					    std::span<const uint8_t> wanted)
{
	if (prev.grey.empty() || cur.grey.empty() || prev.grey.size() != cur.grey.size() || prev.keypoints.empty())
		return {};
	std::vector<uint8_t> matched(prev.keypoints.size(), 0); // 1: not to be followed
	for (const Match &m : matches)
		matched[static_cast<size_t>(m.prev)] = 1;
	if (wanted.size() == prev.keypoints.size())
		for (size_t i = 0; i < matched.size(); ++i)
			matched[i] |= wanted[i] == 0 ? 1 : 0;
	const bool use_prediction = predicted.size() == prev.keypoints.size();
	std::vector<int> index;
	std::vector<cv::Point2f> from, to;
	for (size_t i = 0; i < prev.keypoints.size(); ++i) {
		const cv::Point2f start = use_prediction ? predicted[i] : prev.keypoints[i].pt;
		if (matched[i] != 0 || !std::isfinite(start.x) || !std::isfinite(start.y))
			continue;
		index.push_back(static_cast<int>(i));
		from.push_back(prev.keypoints[i].pt);
		to.push_back(start);
	}
	if (index.empty())
		return {};
	std::vector<cv::Mat> prev_scratch, cur_scratch;
	const std::vector<cv::Mat> &prev_pyramid = pyramid_of(prev, prev_scratch, params);
	const std::vector<cv::Mat> &cur_pyramid = pyramid_of(cur, cur_scratch, params);
	std::vector<uchar> status, back_status;
	std::vector<float> error;
	follow_by_lk(prev_pyramid, cur_pyramid, from, to, status, params, error);
	std::vector<cv::Point2f> back = from;
	follow_by_lk(cur_pyramid, prev_pyramid, to, back, back_status, params);
	const float back2 = params.rescue_back_px * params.rescue_back_px;
	// The windows' difference a followed point may have: a multiple of the frame's median, so the gate follows
	// the footage's noise and contrast.
	float max_error = std::numeric_limits<float>::infinity();
	if (params.follow_max_error_ratio > 0) {
		std::vector<float> landed_errors;
		landed_errors.reserve(error.size());
		for (size_t k = 0; k < error.size(); ++k)
			if (status[k] != 0)
				landed_errors.push_back(error[k]);
		if (!landed_errors.empty()) {
			auto middle = landed_errors.begin() + static_cast<std::ptrdiff_t>(landed_errors.size() / 2);
			std::nth_element(landed_errors.begin(), middle, landed_errors.end());
			// At least a grey level: on clean synthetic frames the median is near 0.
			max_error = params.follow_max_error_ratio * std::max(*middle, 1.0F);
		}
	}
	const auto inside = [&](cv::Point2f p) {
		return p.x >= 0 && p.y >= 0 && p.x < static_cast<float>(cur.grey.cols) &&
		       p.y < static_cast<float>(cur.grey.rows);
	};
	std::vector<FollowedPoint> followed;
	for (size_t k = 0; k < index.size(); ++k) {
		const cv::Point2f round_trip = back[k] - from[k];
		if (status[k] == 0 || back_status[k] == 0 || !inside(to[k]) || !(round_trip.dot(round_trip) <= back2) ||
		    error[k] > max_error)
			continue;
		const cv::Point2f across =
			aperture_ratio > 0 && prev_pyramid.size() > 1
				? edge_across_in(prev_pyramid[1], from[k], params.rescue_window_px, aperture_ratio)
				: cv::Point2f(0, 0);
		followed.push_back({index[k], to[k], across});
	}
	return followed;
}

std::vector<FollowedPoint> lost_corners(std::span<const FollowedPoint> followed, const FrameFeatures &cur,
					std::span<const Match> matches, float clear_px)
{
	// The matched keypoints by row, so each followed point looks only at those within clear_px of its row.
	std::vector<cv::Point2f> taken;
	taken.reserve(matches.size());
	for (const Match &m : matches)
		taken.push_back(cur.keypoints[static_cast<size_t>(m.cur)].pt);
	std::sort(taken.begin(), taken.end(), [](cv::Point2f a, cv::Point2f b) { return a.y < b.y; });
	const float clear2 = clear_px * clear_px;
	const auto followed_already = [&](cv::Point2f at) {
		auto it = std::lower_bound(taken.begin(), taken.end(), at.y - clear_px,
					   [](cv::Point2f p, float y) { return p.y < y; });
		for (; it != taken.end() && it->y <= at.y + clear_px; ++it) {
			const cv::Point2f d = *it - at;
			if (d.dot(d) < clear2)
				return true;
		}
		return false;
	};
	std::vector<FollowedPoint> kept;
	for (const FollowedPoint &f : followed)
		if (f.across == cv::Point2f(0, 0) && !followed_already(f.at))
			kept.push_back(f);
	return kept;
}

int refine_matches(const FrameFeatures &prev, const FrameFeatures &cur, std::span<const cv::Point2f> prev_pts,
		   std::span<cv::Point2f> cur_pts, const MatchParams &params)
{
	if (prev_pts.empty() || prev_pts.size() != cur_pts.size() || prev.grey.empty() || cur.grey.empty() ||
	    prev.grey.size() != cur.grey.size())
		return 0;
	std::vector<cv::Mat> prev_scratch, cur_scratch;
	const std::vector<cv::Mat> &prev_pyramid = pyramid_of(prev, prev_scratch, params);
	const std::vector<cv::Mat> &cur_pyramid = pyramid_of(cur, cur_scratch, params);
	const std::vector<cv::Point2f> from(prev_pts.begin(), prev_pts.end());
	std::vector<cv::Point2f> to(cur_pts.begin(), cur_pts.end());
	std::vector<uchar> status;
	std::vector<float> error;
	const cv::Size window(params.subpixel_window_px, params.subpixel_window_px);
	// Two levels of the frames' pyramid (built once per frame in the extract stage, with the rescue's).
	cv::calcOpticalFlowPyrLK(prev_pyramid, cur_pyramid, from, to, status, error, window, 1,
				 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.01),
				 cv::OPTFLOW_USE_INITIAL_FLOW);
	int refined = 0;
	const float max2 = params.subpixel_max_shift_px * params.subpixel_max_shift_px;
	for (size_t i = 0; i < to.size(); ++i) {
		const cv::Point2f shift = to[i] - cur_pts[i];
		if (status[i] == 0 || !std::isfinite(to[i].x) || !std::isfinite(to[i].y) || shift.dot(shift) > max2)
			continue;
		cur_pts[i] = to[i];
		++refined;
	}
	return refined;
}

} // namespace stereod::vision
