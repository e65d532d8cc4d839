#include "drivers/calibration_file.hpp"

#include <filesystem>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/persistence.hpp>

namespace stereod::drivers {
namespace {

/// One matrix entry of the file as `rows x cols` doubles; throws naming the key when absent or misshapen.
template <int Rows, int Cols>
cv::Matx<double, Rows, Cols> matrix(const cv::FileStorage &file, const std::string &path, const char *key)
{
	cv::Mat m;
	file[key] >> m;
	if (m.empty())
		throw CalibrationError(path + ": no '" + key + "' (an OpenCV stereo calibration has M1 D1 M2 D2 R T)");
	if (m.total() != static_cast<size_t>(Rows * Cols))
		throw CalibrationError(path + ": '" + key + "' has " + std::to_string(m.rows) + "x" +
				       std::to_string(m.cols) + " values, expected " + std::to_string(Rows) + "x" +
				       std::to_string(Cols));
	m.convertTo(m, CV_64F);
	return cv::Matx<double, Rows, Cols>(m.reshape(1, Rows));
}

std::vector<double> coefficients(const cv::FileStorage &file, const char *key)
{
	cv::Mat m;
	file[key] >> m;
	if (m.empty())
		return {};
	m.convertTo(m, CV_64F);
	return std::vector<double>(m.reshape(1, 1));
}

} // namespace

geometry::PairCalibration read_calibration(const std::string &path)
{
	std::error_code ec;
	if (!std::filesystem::is_regular_file(path, ec))
		throw CalibrationError(path + ": no such file");
	cv::FileStorage file;
	try {
		file.open(path, cv::FileStorage::READ);
	} catch (const cv::Exception &e) {
		throw CalibrationError(path + ": not an OpenCV YAML/XML/JSON file (" + e.msg + ")");
	}
	if (!file.isOpened())
		throw CalibrationError(path + ": cannot be read as an OpenCV YAML/XML/JSON file");
	geometry::PairCalibration c;
	try {
		c.k_left = matrix<3, 3>(file, path, "M1");
		c.k_right = matrix<3, 3>(file, path, "M2");
		c.distortion_left = coefficients(file, "D1");
		c.distortion_right = coefficients(file, "D2");
		c.r = matrix<3, 3>(file, path, "R");
		c.t = cv::Vec3d(matrix<3, 1>(file, path, "T").val);
		if (!file["image_width"].empty() || !file["image_height"].empty())
			c.image_size =
				cv::Size(static_cast<int>(file["image_width"]), static_cast<int>(file["image_height"]));
		if (!file["P1"].empty() || !file["P2"].empty() || !file["R1"].empty() || !file["R2"].empty())
			c.rectifying = geometry::PairCalibration::Rectifying{
				matrix<3, 3>(file, path, "R1"), matrix<3, 3>(file, path, "R2"),
				matrix<3, 4>(file, path, "P1"), matrix<3, 4>(file, path, "P2")};
	} catch (const cv::Exception &e) {
		throw CalibrationError(path + ": " + e.msg);
	}
	return c;
}

void write_calibration(const std::string &path, const geometry::PairCalibration &c, cv::Size image,
		       const CalibrationReport &report)
{
	cv::FileStorage file;
	try {
		file.open(path, cv::FileStorage::WRITE);
	} catch (const cv::Exception &e) {
		throw CalibrationError(path + ": " + e.msg);
	}
	if (!file.isOpened())
		throw CalibrationError(path +
				       ": cannot be written (the extension chooses the format: .yml, .xml, .json)");
	// The rectification make_rectification computes, so other tools reading the file get the same maps.
	cv::Mat r1, r2, p1, p2, q;
	cv::stereoRectify(c.k_left, c.distortion_left, c.k_right, c.distortion_right, image, c.r, c.t, r1, r2, p1, p2,
			  q, cv::CALIB_ZERO_DISPARITY, 0, image);
	file << "image_width" << image.width << "image_height" << image.height;
	file << "M1" << cv::Mat(c.k_left) << "D1" << cv::Mat(c.distortion_left, true).reshape(1, 1);
	file << "M2" << cv::Mat(c.k_right) << "D2" << cv::Mat(c.distortion_right, true).reshape(1, 1);
	file << "R" << cv::Mat(c.r) << "T" << cv::Mat(c.t);
	file << "R1" << r1 << "R2" << r2 << "P1" << p1 << "P2" << p2 << "Q" << q;
	file << "rms_px" << report.rms_px << "left_rms_px" << report.left_rms_px << "right_rms_px"
	     << report.right_rms_px << "pairs" << report.pairs << "square_size_m" << report.square_size_m;
}

} // namespace stereod::drivers
