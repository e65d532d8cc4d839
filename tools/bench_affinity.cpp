// Affinity Propagation timing: the sparse k-nearest form the grouping stage uses against the textbook dense
// algorithm, on the same samples in the same run (this machine is noisy: compare rows, not runs).
//   build/tools/bench_affinity [--sizes 250,500,1000,3000] [--dense-max 1000] [--repeat 5]
// Samples: 6-d (seed 002's scale, row, column, disparity, flow u, v), 12 groups of points around random
// centres plus 10 % scattered points, already normalised (unit spread per dimension within a group).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>

#include <CLI/CLI.hpp>

#include "core/vision/affinity.hpp"

using namespace stereod::vision;

namespace {

cv::Mat samples_of(int n, unsigned seed)
{
	std::mt19937 rng(seed);
	std::uniform_real_distribution<float> centre(-30.f, 30.f);
	std::normal_distribution<float> spread(0.f, 1.f);
	std::vector<std::array<float, 6>> centres(12);
	for (auto &c : centres)
		for (auto &v : c)
			v = centre(rng);
	cv::Mat out(n, 6, CV_32F);
	for (int i = 0; i < n; ++i) {
		const bool scattered = i % 10 == 9;
		const auto &c = centres[static_cast<size_t>(i) % centres.size()];
		for (int d = 0; d < 6; ++d)
			out.at<float>(i, d) = scattered ? centre(rng) : c[static_cast<size_t>(d)] + spread(rng);
	}
	return out;
}

template <typename F>
double best_ms(int repeat, F &&run)
{
	double best = 1e30;
	for (int r = 0; r < repeat; ++r) {
		const auto t0 = std::chrono::steady_clock::now();
		run();
		best = std::min(
			best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
	}
	return best;
}

} // namespace

int main(int argc, char **argv)
{
	CLI::App app{"Affinity Propagation: sparse (k nearest) against dense"};
	std::vector<int> sizes{250, 500, 1000, 3000};
	int dense_max = 1000, repeat = 5;
	AffinityParams params;
	app.add_option("--sizes", sizes)->delimiter(',');
	app.add_option("--dense-max", dense_max, "largest N the dense algorithm runs on");
	app.add_option("--repeat", repeat);
	app.add_option("--neighbours", params.neighbours);
	app.add_option("--damping", params.damping);
	app.add_option("--max-iterations", params.max_iterations);
	app.add_flag("--symmetric", params.symmetric, "link k-nearest pairs both ways");
	double preference = 0;
	app.add_option("--preference", preference, "a fixed preference instead of the seed's minimum similarity");
	CLI11_PARSE(app, argc, argv);
	if (app.count("--preference") > 0)
		params.preference = preference;
	std::printf(
		"| points | sparse k=%d ms (best of %d) | iterations | clusters | dense ms | iterations | clusters |\n",
		params.neighbours, repeat);
	std::printf("|---|---|---|---|---|---|---|\n");
	AffinityPropagation ap;
	for (const int n : sizes) {
		const cv::Mat samples = samples_of(n, 11);
		AffinityResult sparse;
		const double sparse_ms = best_ms(repeat, [&] { sparse = ap.cluster(samples, params); });
		if (n <= dense_max) {
			AffinityResult dense;
			const double dense_ms = best_ms(std::min(repeat, 2),
							[&] { dense = affinity_propagation_dense(samples, params); });
			std::printf("| %d | %.2f | %d | %d | %.1f | %d | %d |\n", n, sparse_ms, sparse.iterations,
				    sparse.clusters, dense_ms, dense.iterations, dense.clusters);
		} else {
			std::printf("| %d | %.2f | %d | %d | - | - | - |\n", n, sparse_ms, sparse.iterations,
				    sparse.clusters);
		}
	}
	return 0;
}
