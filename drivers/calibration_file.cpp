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
	// The rectification the daemon uses, so other tools reading the file get the same maps; Q (disparity
	// to depth) as cv::stereoRectify forms it with zero disparity at infinity.
	const auto rect = geometry::rectifying_for(c, image);
	const double f = rect.p_left(0, 0), tx = rect.p_right(0, 3) / rect.p_right(0, 0);
	const cv::Matx44d q(1, 0, 0, -rect.p_left(0, 2), 0, 1, 0, -rect.p_left(1, 2), 0, 0, 0, f, 0, 0, -1 / tx, 0);
	file << "image_width" << image.width << "image_height" << image.height;
	file << "M1" << cv::Mat(c.k_left) << "D1" << cv::Mat(c.distortion_left, true).reshape(1, 1);
	file << "M2" << cv::Mat(c.k_right) << "D2" << cv::Mat(c.distortion_right, true).reshape(1, 1);
	file << "R" << cv::Mat(c.r) << "T" << cv::Mat(c.t);
	file << "R1" << cv::Mat(rect.r_left) << "R2" << cv::Mat(rect.r_right) << "P1" << cv::Mat(rect.p_left) << "P2"
	     << cv::Mat(rect.p_right) << "Q" << cv::Mat(q);
	file << "rms_px" << report.rms_px << "left_rms_px" << report.left_rms_px << "right_rms_px"
	     << report.right_rms_px << "pairs" << report.pairs << "square_size_m" << report.square_size_m;
}

} // namespace stereod::drivers
