// Affinity Propagation clusters frame after frame without allocating once it has seen the largest size (issue
// 16: "no allocation per frame"): the sparse links, the messages and the result live in the object and are
// reused. Counted with the process-wide malloc counter (malloc_counter.hpp), in the allocation binary.
#include <gtest/gtest.h>

#include <random>

#include "core/vision/affinity.hpp"
#include "tests/alloc/malloc_counter.hpp"

using stereod::test::allocations_during;
using namespace stereod::vision;

namespace {

/// `n` 6-d samples around `groups` centres (the grouping stage's sample layout), seeded.
cv::Mat samples_of(int n, int groups, unsigned seed)
{
	std::mt19937 rng(seed);
	std::uniform_real_distribution<float> centre(-20.F, 20.F);
	std::normal_distribution<float> spread(0.F, 1.F);
	std::vector<std::array<float, 6>> centres(static_cast<size_t>(groups));
	for (auto &c : centres)
		for (auto &v : c)
			v = centre(rng);
	cv::Mat out(n, 6, CV_32F);
	for (int i = 0; i < n; ++i)
		for (int d = 0; d < 6; ++d)
			out.at<float>(i, d) =
				centres[static_cast<size_t>(i % groups)][static_cast<size_t>(d)] + spread(rng);
	return out;
}

} // namespace

TEST(ClusteringAllocations, AffinityPropagationReusesItsBuffersFrameAfterFrame)
{
	for (const bool symmetric : {false, true}) {
		AffinityParams params;
		params.symmetric = symmetric;
		AffinityPropagation ap;
		// The first frame at the grouping's cap (groups.max_points, 300) sizes the buffers.
		cv::Mat first = ap.sample_buffer(300, 6);
		samples_of(300, 5, 1).copyTo(first);
		EXPECT_GT(ap.cluster(first, params).clusters, 0);
		// Frames after it, as large or smaller, other samples and other numbers of clusters: nothing.
		for (const auto &[n, groups, seed] :
		     {std::tuple{300, 3, 2U}, {120, 7, 3U}, {300, 9, 4U}, {37, 2, 5U}}) {
			const cv::Mat made = samples_of(n, groups, seed);
			int clusters = 0;
			// As the grouping stage does it: the samples written into the object's own buffer.
			EXPECT_EQ(allocations_during([&] {
					  cv::Mat samples = ap.sample_buffer(n, 6);
					  made.copyTo(samples);
					  clusters = ap.cluster(samples, params).clusters;
				  }),
				  0U)
				<< n << " samples, " << (symmetric ? "symmetric" : "k nearest");
			EXPECT_GT(clusters, 0);
		}
	}
}
