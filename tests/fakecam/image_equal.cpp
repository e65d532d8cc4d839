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
		// Where: the rows spanned, and how many of A's differing samples are zero (a hole left by lost data
		// looks different from a shifted or foreign picture).
		int first_row = -1, last_row = -1, zeros = 0;
		const cv::Mat flat_a = a.reshape(1);
		for (int y = 0; y < diff.rows; ++y) {
			if (cv::countNonZero(diff.row(y)) == 0)
				continue;
			if (first_row < 0)
				first_row = y;
			last_row = y;
			for (int x = 0; x < diff.cols; ++x)
				zeros += diff.at<uchar>(y, x) != 0 && flat_a.at<uchar>(y, x) == 0 ? 1 : 0;
		}
		std::printf("differ: %d of %d samples, rows %d-%d, %d of them zero in %s\n", differing,
			    static_cast<int>(diff.total()), first_row, last_row, zeros, argv[1]);
		return 1;
	}
	return 0;
}
