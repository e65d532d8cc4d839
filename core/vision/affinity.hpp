#pragma once
// Affinity Propagation (Frey and Dueck, Science 2007), as seed 002 section 3.3 uses it: clusters without being
// told how many, every sample either an exemplar or assigned to one.
//
// Sparse form: each sample exchanges messages only with its k nearest neighbours (and itself), which keeps a
// frame's clustering O(N k) per iteration instead of O(N^2); with k >= N - 1 it is the dense algorithm. The
// similarity is the negative squared distance; the preference (every sample's self-similarity, which sets how
// many clusters come out) is the minimum similarity over all pairs, as the seed chooses it, times
// `preference_scale`, unless `preference` is given.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

namespace stereod::vision {

struct AffinityParams {
	int neighbours = 24;  ///< k: messages to the k nearest samples only (sparsity)
	double damping = 0.7; ///< lambda in [0.5, 1): new = lambda old + (1 - lambda) update
	int max_iterations = 200;
	int convergence_iterations = 15;  ///< stop when the exemplars stayed the same this many iterations
	double preference_scale = 1.0;	  ///< x the minimum similarity (seed 002)
	std::optional<double> preference; ///< overrides the seed's choice when set
	bool symmetric = false; ///< j among i's k nearest links them both ways (a symmetric sparse similarity)
};

struct AffinityResult {
	std::vector<int> exemplar; ///< per sample: the index of its cluster's exemplar
	int clusters = 0;
	int iterations = 0;
	bool converged = false;
	double preference = 0; ///< the one used
};

/// Reusable buffers: a caller that keeps one clusters frame after frame without allocating once the
/// largest size has been seen.
class AffinityPropagation
{
public:
	/// Clusters the rows of `samples` (N x D, CV_32F); N = 0 gives an empty result, N = 1 one cluster.
	/// The result lives in this object until the next call.
	const AffinityResult &cluster(const cv::Mat &samples, const AffinityParams &params);

	/// A rows x cols CV_32F matrix over storage this object keeps (grown, never shrunk), for the caller to fill
	/// with the next call's samples, so that they allocate nothing either once the largest size has been
	/// seen. Valid until the next call of this.
	cv::Mat sample_buffer(int rows, int cols);

	/// The largest squared distance between two rows of `data` (n x dims), exactly.
	float farthest_pair(const float *data, size_t n, int dims);

private:
	AffinityResult result_;
	std::vector<float> sample_storage_;
	std::vector<float> centre_, radius_;
	// Edges in row-major order: row i's edges are [row_start_[i], row_start_[i + 1]); its last is (i, i).
	std::vector<uint32_t> row_start_, column_;
	std::vector<float> similarity_, responsibility_, availability_;
	std::vector<uint32_t> self_edge_;
	std::vector<float> positive_sum_, self_responsibility_; ///< per column, for the availabilities
	std::vector<std::pair<float, uint32_t>> nearest_;	///< one sample's k nearest so far (a max-heap)
	struct Link {
		uint32_t row, column;
		float similarity;
	};
	std::vector<Link> links_; ///< symmetric: every pair both ways
	std::vector<uint32_t> order_;
	std::vector<uint8_t> exemplar_flag_;
	std::vector<int> stable_exemplars_;
};

/// The textbook dense algorithm on full N x N matrices (every sample messages every other), written
/// straight from the paper's update rules: the reference the tests and the benchmark hold the sparse one to.
AffinityResult affinity_propagation_dense(const cv::Mat &samples, const AffinityParams &params);

} // namespace stereod::vision
