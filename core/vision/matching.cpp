#include "core/vision/matching.hpp"

#include <bit>
#include <cstring>
#include <limits>

#include <opencv2/features2d.hpp>

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
	std::vector<int> col_best(static_cast<size_t>(n_cur), std::numeric_limits<int>::max());
	std::vector<int> col_arg(static_cast<size_t>(n_cur), kUnset);
	struct RowBest {
		int best = std::numeric_limits<int>::max(), second = std::numeric_limits<int>::max(), arg = kUnset;
	};
	std::vector<RowBest> rows(static_cast<size_t>(n_prev));
	for (int i = 0; i < n_prev; ++i) {
		hamming_rows(prev_words.ptr<uint64_t>(i), cur_words.ptr<uint64_t>(0), n_cur, words, distances.data());
		RowBest &r = rows[static_cast<size_t>(i)];
		for (int j = 0; j < n_cur; ++j) {
			const int d = distances[static_cast<size_t>(j)];
			if (d < r.best) {
				r.second = r.best;
				r.best = d;
				r.arg = j;
			} else if (d < r.second) {
				r.second = d;
			}
			if (d < col_best[static_cast<size_t>(j)]) {
				col_best[static_cast<size_t>(j)] = d;
				col_arg[static_cast<size_t>(j)] = i;
			}
		}
	}
	std::vector<Match> matches;
	matches.reserve(static_cast<size_t>(n_prev));
	for (int i = 0; i < n_prev; ++i) {
		const RowBest &r = rows[static_cast<size_t>(i)];
		if (r.arg == kUnset || r.best > params.max_distance)
			continue;
		if (r.second != std::numeric_limits<int>::max() &&
		    static_cast<float>(r.best) > params.ratio * static_cast<float>(r.second))
			continue;
		if (params.cross_check && col_arg[static_cast<size_t>(r.arg)] != i)
			continue;
		matches.push_back({i, r.arg, static_cast<float>(r.best)});
	}
	return matches;
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

} // namespace

std::vector<Match> match_features(const FrameFeatures &prev, const FrameFeatures &cur, const MatchParams &params)
{
	if (prev.descriptors.empty() || cur.descriptors.empty())
		return {};
	if (cur.norm_type == cv::NORM_HAMMING && prev.descriptors.type() == CV_8U && prev.descriptors.cols % 8 == 0 &&
	    prev.descriptors.cols == cur.descriptors.cols)
		return match_binary(prev.descriptors, cur.descriptors, params);
	return match_float(prev.descriptors, cur.descriptors, params, cur.norm_type);
}

} // namespace stereod::vision
