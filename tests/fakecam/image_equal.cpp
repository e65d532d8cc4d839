// image_equal A B: exit 0 when the two images hold the same pixels (same size, type and bytes), else print
// where they differ and exit 1. Lossless formats only make sense here (PNG, PGM).
#include <cstdio>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

int main(int argc, char **argv)
{
	if (argc != 3) {
		std::fprintf(stderr, "usage: image_equal A B\n");
		return 2;
	}
	const cv::Mat a = cv::imread(argv[1], cv::IMREAD_UNCHANGED), b = cv::imread(argv[2], cv::IMREAD_UNCHANGED);
	if (a.empty() || b.empty()) {
		std::fprintf(stderr, "image_equal: cannot read %s\n", a.empty() ? argv[1] : argv[2]);
		return 2;
	}
	if (a.size() != b.size() || a.type() != b.type()) {
		std::printf("differ: %dx%d type %d vs %dx%d type %d\n", a.cols, a.rows, a.type(), b.cols, b.rows,
			    b.type());
		return 1;
	}
	cv::Mat diff;
	cv::compare(a.reshape(1), b.reshape(1), diff, cv::CMP_NE);
	const int differing = cv::countNonZero(diff);
	if (differing > 0) {
		std::printf("differ: %d of %d samples\n", differing, static_cast<int>(diff.total()));
		return 1;
	}
	return 0;
}
