// Affinity Propagation and the grouping of moving points, on constructed data with known answers.
#include <random>

#include <gtest/gtest.h>

#include "core/vision/affinity.hpp"

using namespace stereod;
using namespace stereod::vision;

namespace {

/// `per_blob` points around each centre, normal with sigma 1, fixed seed.
cv::Mat blobs(const std::vector<cv::Point2f> &centres, int per_blob, unsigned seed = 7)
{
	std::mt19937 rng(seed);
	std::normal_distribution<float> noise(0.f, 1.f);
	cv::Mat samples(static_cast<int>(centres.size()) * per_blob, 2, CV_32F);
	int row = 0;
	for (const auto &c : centres)
		for (int i = 0; i < per_blob; ++i, ++row) {
			samples.at<float>(row, 0) = c.x + noise(rng);
			samples.at<float>(row, 1) = c.y + noise(rng);
		}
	return samples;
}

} // namespace

TEST(AffinityPropagation, FindsSeparatedBlobsWithoutBeingToldHowMany)
{
	for (const auto &centres : std::vector<std::vector<cv::Point2f>>{
		     {{0, 0}, {20, 0}, {0, 20}}, {{0, 0}, {25, 5}}, {{0, 0}, {20, 20}, {40, 0}, {-20, 30}, {60, 40}}}) {
		const int per_blob = 40;
		const cv::Mat samples = blobs(centres, per_blob);
		AffinityPropagation ap;
		const AffinityResult &result = ap.cluster(samples, AffinityParams{});
		EXPECT_TRUE(result.converged);
		EXPECT_EQ(result.clusters, static_cast<int>(centres.size()));
		// Every blob is one cluster and no two blobs share one.
		for (size_t b = 0; b < centres.size(); ++b) {
			const int exemplar = result.exemplar[b * per_blob];
			for (int i = 0; i < per_blob; ++i)
				EXPECT_EQ(result.exemplar[b * per_blob + static_cast<size_t>(i)], exemplar)
					<< "blob " << b;
			for (size_t other = b + 1; other < centres.size(); ++other)
				EXPECT_NE(result.exemplar[other * per_blob], exemplar);
		}
	}
}

TEST(AffinityPropagation, SparseWithAllNeighboursIsTheDenseAlgorithm)
{
	const cv::Mat samples = blobs({{0, 0}, {12, 3}, {5, 14}}, 20, 3);
	AffinityParams params;
	params.neighbours = samples.rows - 1;
	AffinityPropagation ap;
	const AffinityResult sparse = ap.cluster(samples, params);
	const AffinityResult dense = affinity_propagation_dense(samples, params);
	EXPECT_EQ(sparse.clusters, dense.clusters);
	EXPECT_EQ(sparse.iterations, dense.iterations);
	EXPECT_EQ(sparse.exemplar, dense.exemplar);
	EXPECT_DOUBLE_EQ(sparse.preference, dense.preference);
}

TEST(AffinityPropagation, PreferenceSetsHowManyClusters)
{
	const cv::Mat samples = blobs({{0, 0}, {20, 0}, {0, 20}}, 30);
	AffinityPropagation ap;
	AffinityParams seed; // the minimum similarity: the three blobs
	EXPECT_EQ(ap.cluster(samples, seed).clusters, 3);
	AffinityParams fewer = seed; // lower, with every sample linked
	fewer.preference_scale = 4;
	fewer.neighbours = samples.rows - 1;
	EXPECT_LE(ap.cluster(samples, fewer).clusters, 3);
	AffinityParams joined = fewer; // a preference far below the blobs' separation: one cluster
	joined.preference_scale = 1;
	joined.preference = -20000;
	joined.damping = 0.9;
	EXPECT_EQ(ap.cluster(samples, joined).clusters, 1);
	AffinityParams many;
	many.preference = -0.01; // above most similarities: many small clusters
	EXPECT_GT(ap.cluster(samples, many).clusters, 10);
}

TEST(AffinityPropagation, TrivialSizes)
{
	AffinityPropagation ap;
	EXPECT_EQ(ap.cluster(cv::Mat(0, 3, CV_32F), {}).clusters, 0);
	const cv::Mat one(1, 3, CV_32F, cv::Scalar(1));
	const auto &r = ap.cluster(one, {});
	EXPECT_EQ(r.clusters, 1);
	EXPECT_EQ(r.exemplar, std::vector<int>{0});
}
