#include "core/vision/affinity.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace stereod::vision {
namespace {

float squared_distance(const float *a, const float *b, int dims)
{
	float sum = 0;
	for (int d = 0; d < dims; ++d) {
		const float diff = a[d] - b[d];
		sum += diff * diff;
	}
	return sum;
}

} // namespace

cv::Mat AffinityPropagation::sample_buffer(int rows, int cols)
{
	CV_Assert(rows >= 0 && cols > 0);
	sample_storage_.resize(static_cast<size_t>(rows) * static_cast<size_t>(cols));
	return {rows, cols, CV_32F, sample_storage_.data()};
}

float AffinityPropagation::farthest_pair(const float *data, size_t n, int dims)
{
	// Exactly, but not over all n^2 / 2 pairs: with r the distance of each sample to the samples' mean, no
	// pair is farther apart than r_i + r_j (the triangle inequality). Samples in order of falling r, the
	// search of a row stops once that bound cannot beat the best so far, and the whole search once twice
	// the row's r cannot. Clustered samples end after a few rows.
	centre_.assign(static_cast<size_t>(dims), 0.F);
	for (size_t i = 0; i < n; ++i)
		for (int d = 0; d < dims; ++d)
			centre_[static_cast<size_t>(d)] += data[i * static_cast<size_t>(dims) + static_cast<size_t>(d)];
	for (float &c : centre_)
		c /= static_cast<float>(n);
	radius_.resize(n);
	order_.resize(n);
	for (size_t i = 0; i < n; ++i)
		radius_[i] = std::sqrt(squared_distance(data + i * static_cast<size_t>(dims), centre_.data(), dims));
	std::iota(order_.begin(), order_.end(), 0u);
	std::sort(order_.begin(), order_.end(), [this](uint32_t a, uint32_t b) { return radius_[a] > radius_[b]; });
	// The bound in squares, a little loose so that rounding never prunes the true farthest pair.
	const auto cannot_beat = [](float bound, float best) { return bound * bound * (1 - 1e-4F) < best; };
	float best = 0;
	for (size_t a = 0; a < n; ++a) {
		const uint32_t i = order_[a];
		if (cannot_beat(2 * radius_[i], best))
			break;
		const float *xi = data + static_cast<size_t>(i) * static_cast<size_t>(dims);
		for (size_t b = a + 1; b < n; ++b) {
			const uint32_t j = order_[b];
			if (cannot_beat(radius_[i] + radius_[j], best))
				break;
			best = std::max(
				best,
				squared_distance(xi, data + static_cast<size_t>(j) * static_cast<size_t>(dims), dims));
		}
	}
	return best;
}

const AffinityResult &AffinityPropagation::cluster(const cv::Mat &samples, const AffinityParams &params)
{
	CV_Assert(samples.empty() || (samples.type() == CV_32F && samples.isContinuous()));
	AffinityResult &result = result_;
	result.clusters = 0;
	result.iterations = 0;
	result.converged = false;
	const auto n = static_cast<size_t>(samples.rows);
	const int dims = samples.cols;
	result.exemplar.assign(n, 0);
	if (n <= 1) {
		result.clusters = static_cast<int>(n);
		result.converged = true;
		return result;
	}
	const auto k = static_cast<size_t>(std::clamp<int>(params.neighbours, 1, static_cast<int>(n) - 1));
	const auto *data = samples.ptr<float>();

	// The seed's preference: the minimum similarity over all pairs, i.e. minus the largest squared distance.
	const float min_similarity = params.preference ? 0.F : -farthest_pair(data, n, dims);

	// The k nearest of each sample, exactly, by a sweep along the dimension with the widest spread: samples
	// sorted on it, each looks outwards from its own place and stops on a side once the distance along that
	// dimension alone exceeds its k-th best so far. Clustered samples (what a frame's movers give) look at a
	// few times k others instead of all n. Ties go to the lower index, so the result is the same whatever
	// the order of the scan.
	int axis = 0;
	{
		float widest = -1;
		for (int d = 0; d < dims; ++d) {
			float lo = std::numeric_limits<float>::infinity(), hi = -lo;
			for (size_t i = 0; i < n; ++i) {
				lo = std::min(lo, data[i * static_cast<size_t>(dims) + static_cast<size_t>(d)]);
				hi = std::max(hi, data[i * static_cast<size_t>(dims) + static_cast<size_t>(d)]);
			}
			if (hi - lo > widest) {
				widest = hi - lo;
				axis = d;
			}
		}
	}
	const auto coordinate = [&](uint32_t i) {
		return data[i * static_cast<size_t>(dims) + static_cast<size_t>(axis)];
	};
	order_.resize(n);
	std::iota(order_.begin(), order_.end(), 0u);
	std::sort(order_.begin(), order_.end(), [&](uint32_t a, uint32_t b) {
		return coordinate(a) < coordinate(b) || (coordinate(a) == coordinate(b) && a < b);
	});
	row_start_.assign(n + 1, 0);
	column_.resize(n * (k + 1));
	similarity_.resize(n * (k + 1));
	nearest_.reserve(k + 1);
	// A max-heap on (distance, index): its top is the worst of the k kept.
	const auto worse = [](const std::pair<float, uint32_t> &a, const std::pair<float, uint32_t> &b) {
		return a < b;
	};
	for (size_t p = 0; p < n; ++p) {
		const uint32_t i = order_[p];
		const float *xi = data + i * static_cast<size_t>(dims);
		const float ci = coordinate(i);
		nearest_.clear();
		const auto consider = [&](uint32_t j) {
			const std::pair<float, uint32_t> candidate{
				squared_distance(xi, data + j * static_cast<size_t>(dims), dims), j};
			if (nearest_.size() < k) {
				nearest_.push_back(candidate);
				std::push_heap(nearest_.begin(), nearest_.end(), worse);
			} else if (candidate < nearest_.front()) {
				std::pop_heap(nearest_.begin(), nearest_.end(), worse);
				nearest_.back() = candidate;
				std::push_heap(nearest_.begin(), nearest_.end(), worse);
			}
		};
		// Out to both sides; a side stops when its next sample is farther along the axis alone than the
		// k-th best (a tie on distance may still win on index, hence <=).
		size_t left = p, right = p + 1;
		bool left_open = left > 0, right_open = right < n;
		while (left_open || right_open) {
			if (left_open) {
				const uint32_t j = order_[left - 1];
				const float gap = ci - coordinate(j);
				if (nearest_.size() == k && gap * gap > nearest_.front().first) {
					left_open = false;
				} else {
					consider(j);
					--left;
					left_open = left > 0;
				}
			}
			if (right_open) {
				const uint32_t j = order_[right];
				const float gap = coordinate(j) - ci;
				if (nearest_.size() == k && gap * gap > nearest_.front().first) {
					right_open = false;
				} else {
					consider(j);
					++right;
					right_open = right < n;
				}
			}
		}
		const size_t base = static_cast<size_t>(i) * (k + 1);
		std::sort_heap(nearest_.begin(), nearest_.end(), worse);
		for (size_t e = 0; e < k; ++e) {
			column_[base + e] = nearest_[e].second;
			similarity_[base + e] = -nearest_[e].first;
		}
		column_[base + k] = i;
	}
	for (size_t i = 0; i < n; ++i)
		row_start_[i + 1] = static_cast<uint32_t>((i + 1) * (k + 1));
	const double preference = params.preference ? *params.preference : params.preference_scale * min_similarity;
	result.preference = preference;
	size_t edges = n * (k + 1);
	self_edge_.resize(n);
	for (size_t i = 0; i < n; ++i) {
		similarity_[i * (k + 1) + k] = static_cast<float>(preference);
		self_edge_[i] = static_cast<uint32_t>(i * (k + 1) + k);
	}
	if (params.symmetric) {
		// j among i's nearest gives the pair both ways: messages flow between them in both directions. The
		// links are placed by row with a counting pass (each row's share known up front), then each row,
		// at most 2 k + 1 long, is sorted by column and its doubles (j and i each among the other's
		// nearest) dropped: no sort over all N k links.
		std::fill(row_start_.begin(), row_start_.end(), 0u);
		for (size_t i = 0; i < n; ++i)
			for (size_t e = i * (k + 1); e < (i + 1) * (k + 1); ++e) {
				++row_start_[i + 1];
				if (column_[e] != i)
					++row_start_[column_[e] + 1];
			}
		std::partial_sum(row_start_.begin(), row_start_.end(), row_start_.begin());
		// How many links a frame's samples make depends on how they lie (between N (k + 1) and N (2 k + 1)):
		// room for the most, so that a later frame of no more samples never grows the buffers.
		const size_t most = n * (2 * k + 1);
		links_.reserve(most);
		column_.reserve(most);
		for (auto *messages : {&similarity_, &responsibility_, &availability_})
			messages->reserve(most);
		links_.resize(row_start_[n]);
		order_.assign(row_start_.begin(), row_start_.end() - 1); // each row's fill cursor
		for (size_t i = 0; i < n; ++i)
			for (size_t e = i * (k + 1); e < (i + 1) * (k + 1); ++e) {
				const uint32_t j = column_[e];
				links_[order_[i]++] = {static_cast<uint32_t>(i), j, similarity_[e]};
				if (j != i)
					links_[order_[j]++] = {j, static_cast<uint32_t>(i), similarity_[e]};
			}
		edges = 0;
		column_.resize(links_.size());
		similarity_.resize(links_.size());
		for (size_t i = 0; i < n; ++i) {
			const auto first = links_.begin() + row_start_[i], last = links_.begin() + row_start_[i + 1];
			std::sort(first, last, [](const Link &x, const Link &y) { return x.column < y.column; });
			row_start_[i] = static_cast<uint32_t>(edges);
			for (auto link = first; link != last; ++link) {
				if (link != first && link->column == (link - 1)->column)
					continue;
				if (link->column == i)
					self_edge_[i] = static_cast<uint32_t>(edges);
				column_[edges] = link->column;
				similarity_[edges] = link->similarity;
				++edges;
			}
		}
		row_start_[n] = static_cast<uint32_t>(edges);
		column_.resize(edges);
		similarity_.resize(edges);
	}
	responsibility_.assign(edges, 0);
	availability_.assign(edges, 0);
	exemplar_flag_.assign(n, 0);
	positive_sum_.resize(n);
	self_responsibility_.resize(n);
	const auto lambda = static_cast<float>(params.damping);
	int unchanged = 0;
	int iteration = 0;
	for (; iteration < params.max_iterations; ++iteration) {
		// Responsibilities: r(i,k) = s(i,k) - max over k' != k of (a(i,k') + s(i,k')). In the same pass
		// over the edges, row by row, each column's sum of positive responsibilities from the others, for
		// the availabilities: scattered into an array of N that stays in cache, where walking the edges
		// column by column would jump about arrays of N k.
		std::fill(positive_sum_.begin(), positive_sum_.end(), 0.F);
		for (size_t i = 0; i < n; ++i) {
			float best = -std::numeric_limits<float>::infinity(), second = best;
			size_t best_edge = 0;
			for (size_t e = row_start_[i]; e < row_start_[i + 1]; ++e) {
				const float v = availability_[e] + similarity_[e];
				if (v > best) {
					second = best;
					best = v;
					best_edge = e;
				} else if (v > second) {
					second = v;
				}
			}
			for (size_t e = row_start_[i]; e < row_start_[i + 1]; ++e) {
				const float update = similarity_[e] - (e == best_edge ? second : best);
				const float r = lambda * responsibility_[e] + (1 - lambda) * update;
				responsibility_[e] = r;
				if (e != self_edge_[i])
					positive_sum_[column_[e]] += std::max(0.F, r);
			}
			self_responsibility_[i] = responsibility_[self_edge_[i]];
		}
		// Availabilities: a(i,k) = min(0, r(k,k) + sum over i' not in {i,k} of max(0, r(i',k)));
		// a(k,k) = sum over i' != k of max(0, r(i',k)).
		for (size_t i = 0; i < n; ++i)
			for (size_t e = row_start_[i]; e < row_start_[i + 1]; ++e) {
				const uint32_t c = column_[e];
				const float update =
					e == self_edge_[i] ? positive_sum_[c]
							   : std::min(0.F, self_responsibility_[c] + positive_sum_[c] -
										   std::max(0.F, responsibility_[e]));
				availability_[e] = lambda * availability_[e] + (1 - lambda) * update;
			}
		bool changed = false;
		for (size_t i = 0; i < n; ++i) {
			const uint8_t is = responsibility_[self_edge_[i]] + availability_[self_edge_[i]] > 0 ? 1 : 0;
			changed = changed || is != exemplar_flag_[i];
			exemplar_flag_[i] = is;
		}
		const bool any = std::any_of(exemplar_flag_.begin(), exemplar_flag_.end(), [](uint8_t f) { return f; });
		unchanged = changed || !any ? 0 : unchanged + 1;
		if (unchanged >= params.convergence_iterations) {
			result.converged = true;
			++iteration;
			break;
		}
	}
	result.iterations = iteration;
	// Assignment: each sample to its most similar exemplar (an exemplar to itself). A sample with no exemplar
	// among its neighbours looks at all of them; with no exemplar at all, the one with the largest
	// r(k,k) + a(k,k) serves.
	stable_exemplars_.clear();
	for (size_t i = 0; i < n; ++i)
		if (exemplar_flag_[i])
			stable_exemplars_.push_back(static_cast<int>(i));
	if (stable_exemplars_.empty()) {
		size_t best = 0;
		for (size_t i = 1; i < n; ++i)
			if (responsibility_[self_edge_[i]] + availability_[self_edge_[i]] >
			    responsibility_[self_edge_[best]] + availability_[self_edge_[best]])
				best = i;
		stable_exemplars_.push_back(static_cast<int>(best));
		exemplar_flag_[best] = 1;
	}
	for (size_t i = 0; i < n; ++i) {
		if (exemplar_flag_[i]) {
			result.exemplar[i] = static_cast<int>(i);
			continue;
		}
		float best = -std::numeric_limits<float>::infinity();
		int chosen = -1;
		for (size_t e = row_start_[i]; e < row_start_[i + 1]; ++e)
			if (e != self_edge_[i] && exemplar_flag_[column_[e]] && similarity_[e] > best) {
				best = similarity_[e];
				chosen = static_cast<int>(column_[e]);
			}
		if (chosen < 0)
			for (const int x : stable_exemplars_) {
				const float s = -squared_distance(
					data + i * static_cast<size_t>(dims),
					data + static_cast<size_t>(x) * static_cast<size_t>(dims), dims);
				if (s > best) {
					best = s;
					chosen = x;
				}
			}
		result.exemplar[i] = chosen;
	}
	result.clusters = static_cast<int>(stable_exemplars_.size());
	return result;
}

AffinityResult affinity_propagation_dense(const cv::Mat &samples, const AffinityParams &params)
{
	CV_Assert(samples.empty() || (samples.type() == CV_32F && samples.isContinuous()));
	AffinityResult result;
	const int n = samples.rows;
	result.exemplar.assign(static_cast<size_t>(n), 0);
	if (n <= 1) {
		result.clusters = n;
		result.converged = true;
		return result;
	}
	cv::Mat s(n, n, CV_64F), r(n, n, CV_64F, cv::Scalar(0)), a(n, n, CV_64F, cv::Scalar(0));
	double min_s = 0;
	for (int i = 0; i < n; ++i)
		for (int j = 0; j < n; ++j) {
			s.at<double>(i, j) = -static_cast<double>(
				squared_distance(samples.ptr<float>(i), samples.ptr<float>(j), samples.cols));
			min_s = std::min(min_s, s.at<double>(i, j));
		}
	result.preference = params.preference ? *params.preference : params.preference_scale * min_s;
	for (int i = 0; i < n; ++i)
		s.at<double>(i, i) = result.preference;
	const double lambda = params.damping;
	std::vector<uint8_t> exemplar(static_cast<size_t>(n), 0);
	int unchanged = 0, iteration = 0;
	for (; iteration < params.max_iterations; ++iteration) {
		for (int i = 0; i < n; ++i) {
			// max over k' != k of a(i,k') + s(i,k'): the row's largest, or its second for the largest's k
			double best = -std::numeric_limits<double>::infinity(), second = best;
			int best_k = 0;
			for (int k = 0; k < n; ++k) {
				const double v = a.at<double>(i, k) + s.at<double>(i, k);
				if (v > best) {
					second = best;
					best = v;
					best_k = k;
				} else if (v > second) {
					second = v;
				}
			}
			for (int k = 0; k < n; ++k)
				r.at<double>(i, k) =
					lambda * r.at<double>(i, k) +
					(1 - lambda) * (s.at<double>(i, k) - (k == best_k ? second : best));
		}
		for (int k = 0; k < n; ++k) {
			double sum = 0; // over i' != k of max(0, r(i',k))
			for (int i = 0; i < n; ++i)
				if (i != k)
					sum += std::max(0.0, r.at<double>(i, k));
			for (int i = 0; i < n; ++i) {
				const double update = i == k ? sum
							     : std::min(0.0, r.at<double>(k, k) + sum -
										     std::max(0.0, r.at<double>(i, k)));
				a.at<double>(i, k) = lambda * a.at<double>(i, k) + (1 - lambda) * update;
			}
		}
		bool changed = false, any = false;
		for (int i = 0; i < n; ++i) {
			const uint8_t is = r.at<double>(i, i) + a.at<double>(i, i) > 0 ? 1 : 0;
			changed = changed || is != exemplar[static_cast<size_t>(i)];
			exemplar[static_cast<size_t>(i)] = is;
			any = any || is;
		}
		unchanged = changed || !any ? 0 : unchanged + 1;
		if (unchanged >= params.convergence_iterations) {
			result.converged = true;
			++iteration;
			break;
		}
	}
	result.iterations = iteration;
	for (int i = 0; i < n; ++i) {
		int chosen = -1;
		double best = -std::numeric_limits<double>::infinity();
		for (int k = 0; k < n; ++k)
			if (exemplar[static_cast<size_t>(k)] && (k == i ? 0.0 : s.at<double>(i, k)) > best &&
			    (exemplar[static_cast<size_t>(i)] == 0 || k == i)) {
				best = k == i ? 0.0 : s.at<double>(i, k);
				chosen = k;
			}
		result.exemplar[static_cast<size_t>(i)] = chosen;
	}
	result.clusters = static_cast<int>(std::count(exemplar.begin(), exemplar.end(), 1));
	return result;
}

} // namespace stereod::vision
