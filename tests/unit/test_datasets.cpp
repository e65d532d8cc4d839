// Each importer on a small fixture built here in the dataset's real layout.
#include <gtest/gtest.h>

#include <cstdio>

#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "drivers/replay/datasets.hpp"
#include "drivers/source.hpp"

using namespace stereod;
using namespace stereod::drivers;
namespace fs = std::filesystem;

namespace {

class TempDir
{
public:
	TempDir()
	{
		path_ = fs::temp_directory_path() /
			("stereod-ds-" + std::to_string(::getpid()) + "-" + std::to_string(counter_++));
		fs::create_directories(path_);
	}
	~TempDir() { fs::remove_all(path_); }
	[[nodiscard]] const fs::path &path() const { return path_; }

private:
	static inline int counter_ = 0;
	fs::path path_;
};

void write_image(const fs::path &file, int value, int type = CV_8UC3)
{
	fs::create_directories(file.parent_path());
	cv::imwrite(file.string(), cv::Mat(24, 32, type, cv::Scalar::all(value)));
}

std::unique_ptr<FrameSource> open(const std::string &driver, const fs::path &path)
{
	SourceConfig config;
	config.driver = driver;
	config.path = path.string();
	return SourceRegistry::with_builtin_drivers().create(config);
}

} // namespace

TEST(Datasets, KittiTimestamps)
{
	EXPECT_EQ(datasets::parse_kitti_timestamp("1970-01-01 00:00:01.500000000"), 1'500'000'000);
	EXPECT_EQ(datasets::parse_kitti_timestamp("2011-09-26 13:02:25.964389445"), 1317042145964389445LL);
	EXPECT_THROW(datasets::parse_kitti_timestamp("yesterday"), std::runtime_error);
}

TEST(Datasets, KittiRawDrive)
{
	TempDir dir;
	for (const char *cam : {"image_02", "image_03"}) {
		fs::create_directories(dir.path() / cam / "data");
		std::ofstream stamps(dir.path() / cam / "timestamps.txt");
		for (int i = 0; i < 3; ++i) {
			write_image(dir.path() / cam / "data" / ("000000000" + std::to_string(i) + ".png"), 10 * i);
			stamps << "2011-09-26 13:02:2" << i << "."
			       << (std::string(cam) == "image_02" ? "100000000" : "100000500") << "\n";
		}
	}
	std::ofstream(dir.path() / "calib_cam_to_cam.txt")
		<< "calib_time: 09-Jan-2012 13:57:47\n"
		<< "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
		   "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n"
		<< "P_rect_03: 7.215377e+02 0.000000e+00 6.095593e+02 -3.395242e+02 0.000000e+00 7.215377e+02 "
		   "1.728540e+02 2.199936e+00 0.000000e+00 0.000000e+00 1.000000e+00 2.729905e-03\n";
	auto source = open("kitti", dir.path());
	EXPECT_TRUE(source->info().geometry.stereo);
	ASSERT_TRUE(source->info().calibration.has_value());
	EXPECT_DOUBLE_EQ(source->info().calibration->fx, 721.5377);
	EXPECT_NEAR(source->info().calibration->baseline_m, 0.532, 0.001) << "KITTI's colour cameras: 0.54 m nominal";
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	int64_t previous = 0;
	for (int i = 0; i < 3; ++i) {
		ASSERT_EQ(source->grab(frame), GrabStatus::Frame);
		EXPECT_EQ(frame.lr_skew_ns, 500);
		EXPECT_EQ(frame.left.at<cv::Vec3b>(0, 0)[0], 10 * i);
		if (i > 0) {
			EXPECT_EQ(frame.device_ns - previous, 1'000'000'000);
		}
		previous = frame.device_ns;
	}
	EXPECT_EQ(source->grab(frame), GrabStatus::EndOfStream);
}

TEST(Datasets, KittiCountMismatchIsAnError)
{
	TempDir dir;
	for (const char *cam : {"image_02", "image_03"}) {
		write_image(dir.path() / cam / "data" / "0000000000.png", 1);
		std::ofstream(dir.path() / cam / "timestamps.txt") << "2011-09-26 13:02:20.0\n2011-09-26 13:02:21.0\n";
	}
	try {
		open("kitti", dir.path());
		FAIL() << "expected an error";
	} catch (const SourceError &e) {
		EXPECT_NE(std::string(e.what()).find("1 images but 2 timestamps"), std::string::npos) << e.what();
	}
}

TEST(Datasets, EurocPairsCamerasByTimestamp)
{
	TempDir dir;
	const fs::path mav = dir.path() / "mav0";
	fs::create_directories(mav / "cam0");
	fs::create_directories(mav / "cam1");
	std::ofstream cam0(mav / "cam0" / "data.csv"), cam1(mav / "cam1" / "data.csv");
	cam0 << "#timestamp [ns],filename\n";
	cam1 << "#timestamp [ns],filename\n";
	const int64_t t0 = 1403636579763555584LL;
	for (int i = 0; i < 4; ++i) {
		const std::string name = std::to_string(t0 + i * 50'000'000LL) + ".png";
		write_image(mav / "cam0" / "data" / name, i, CV_8UC1);
		cam0 << t0 + i * 50'000'000LL << "," << name << "\n";
		if (i == 2)
			continue; // cam1 lost a frame
		write_image(mav / "cam1" / "data" / name, i, CV_8UC1);
		cam1 << t0 + i * 50'000'000LL << "," << name << "\n";
	}
	cam0.close();
	cam1.close();
	const auto index = datasets::euroc(dir.path().string());
	ASSERT_EQ(index.entries.size(), 3U);
	EXPECT_EQ(index.entries[2].device_ns, t0 + 150'000'000LL);
	ASSERT_EQ(index.notes.size(), 1U);
	auto source = open("euroc", dir.path());
	EXPECT_EQ(source->info().geometry.format, PixelFormat::Mono8);
	EXPECT_NEAR(source->info().geometry.nominal_fps, 2 / 0.15, 1e-6) << "3 frames over 150 ms";
}

TEST(Datasets, TumAssociatesDepthByNearestTime)
{
	TempDir dir;
	std::ofstream rgb(dir.path() / "rgb.txt"), depth(dir.path() / "depth.txt");
	rgb << "# color images\n# file: 'x.bag'\n# timestamp filename\n";
	depth << "# depth maps\n";
	for (int i = 0; i < 3; ++i) {
		const std::string t = "1305031102." + std::to_string(100000 + i * 33333);
		const std::string td = "1305031102." + std::to_string(110000 + i * 33333); // 10 ms later
		write_image(dir.path() / "rgb" / (t + ".png"), 50 + i);
		fs::create_directories(dir.path() / "depth");
		cv::imwrite((dir.path() / "depth" / (td + ".png")).string(),
			    cv::Mat(24, 32, CV_16UC1, cv::Scalar(5000 * (i + 1))));
		rgb << t << " rgb/" << t << ".png\n";
		depth << td << " depth/" << td << ".png\n";
	}
	rgb.close();
	depth.close();
	auto source = open("tum", dir.path());
	ASSERT_TRUE(source->info().geometry.depth);
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	for (int i = 0; i < 3; ++i) {
		ASSERT_EQ(source->grab(frame), GrabStatus::Frame);
		EXPECT_FLOAT_EQ(frame.depth.at<float>(5, 5), static_cast<float>(i + 1)) << "5000 units per metre";
		EXPECT_EQ(frame.device_ns, 1305031102'000000000LL + (100000 + i * 33333) * 1000LL);
	}
	// A folder that names no Freiburg camera: ROS's default intrinsics, and a note saying so.
	ASSERT_TRUE(source->info().calibration);
	EXPECT_DOUBLE_EQ(source->info().calibration->fx, 525.0);
	EXPECT_DOUBLE_EQ(source->info().calibration->cy, 239.5);
}

TEST(Datasets, TumIntrinsicsFollowTheSequenceName)
{
	std::vector<std::string> notes;
	const auto fr3 = datasets::tum_intrinsics("rgbd_dataset_freiburg3_walking_xyz", notes);
	EXPECT_DOUBLE_EQ(fr3.fx, 535.4);
	EXPECT_DOUBLE_EQ(fr3.fy, 539.2);
	EXPECT_DOUBLE_EQ(fr3.cx, 320.1);
	EXPECT_DOUBLE_EQ(fr3.cy, 247.6);
	const auto fr1 = datasets::tum_intrinsics("rgbd_dataset_freiburg1_xyz", notes);
	EXPECT_DOUBLE_EQ(fr1.fx, 525.0);
	EXPECT_TRUE(notes.empty());
	datasets::tum_intrinsics("my_sequence", notes);
	ASSERT_EQ(notes.size(), 1U);
	EXPECT_NE(notes[0].find("ROS's default"), std::string::npos);
}

TEST(Datasets, FolderPairWithAndWithoutTimestamps)
{
	TempDir dir;
	for (int i = 0; i < 3; ++i) {
		write_image(dir.path() / "left" / ("l" + std::to_string(i) + ".png"), i);
		write_image(dir.path() / "right" / ("r" + std::to_string(i) + ".png"), i);
	}
	auto index = datasets::folder_pair(dir.path().string(), 10.0);
	ASSERT_EQ(index.entries.size(), 3U);
	EXPECT_EQ(index.entries[2].device_ns, 200'000'000);
	std::ofstream(dir.path() / "timestamps.txt") << "5.0\n5.5\n6.25\n";
	index = datasets::folder_pair(dir.path().string(), 10.0);
	EXPECT_EQ(index.entries[2].device_ns, 6'250'000'000);
	fs::remove(dir.path() / "right" / "r2.png");
	EXPECT_THROW(datasets::folder_pair(dir.path().string(), 10.0), SourceError);
}

TEST(Datasets, UnreadableImageIsMarkedCorruptAndTheStreamGoesOn)
{
	TempDir dir;
	for (int i = 0; i < 3; ++i) {
		write_image(dir.path() / "left" / ("l" + std::to_string(i) + ".png"), i);
		write_image(dir.path() / "right" / ("r" + std::to_string(i) + ".png"), i);
	}
	std::ofstream(dir.path() / "right" / "r1.png", std::ios::trunc) << "not a png";
	auto source = open("folder", dir.path());
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	std::vector<FrameStatus> statuses;
	while (source->grab(frame) == GrabStatus::Frame)
		statuses.push_back(frame.status);
	EXPECT_EQ(statuses, (std::vector<FrameStatus>{FrameStatus::Ok, FrameStatus::Corrupt, FrameStatus::Ok}));
}

TEST(Datasets, MissingFolderNamesThePath)
{
	try {
		open("tum", "/nonexistent/tum-seq");
		FAIL();
	} catch (const SourceError &e) {
		EXPECT_NE(std::string(e.what()).find("/nonexistent/tum-seq"), std::string::npos);
	}
}

TEST(Datasets, VideoFileTimestampsFollowTheFrameRate)
{
	TempDir dir;
	const std::string path = (dir.path() / "clip.avi").string();
	{
		cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 12.5, cv::Size(64, 48));
		ASSERT_TRUE(writer.isOpened());
		for (int i = 0; i < 6; ++i)
			writer.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(20 * i, 0, 0)));
	}
	auto source = open("video", dir.path() / "clip.avi");
	EXPECT_FALSE(source->info().geometry.stereo);
	StereoFrame frame;
	frame.allocate(source->info().geometry);
	std::vector<int64_t> stamps;
	while (source->grab(frame) == GrabStatus::Frame)
		stamps.push_back(frame.device_ns);
	ASSERT_EQ(stamps.size(), 6U);
	for (size_t i = 0; i < stamps.size(); ++i)
		EXPECT_EQ(stamps[i], static_cast<int64_t>(i) * 80'000'000) << "12.5 fps -> 80 ms apart";
}

TEST(DatasetDefects, KittiWithAFrameMissingOnOneSideStops)
{
	// It used to warn and pair by index: after the gap, pairs were a second apart and still `ok`.
	TempDir dir;
	for (const char *cam : {"image_02", "image_03"}) {
		const int frames = std::string(cam) == "image_02" ? 3 : 2;
		fs::create_directories(dir.path() / cam / "data");
		std::ofstream stamps(dir.path() / cam / "timestamps.txt");
		for (int i = 0; i < frames; ++i) {
			char name[32];
			std::snprintf(name, sizeof(name), "%010d.png", i);
			write_image(dir.path() / cam / "data" / name, i);
			stamps << "2011-09-26 13:02:2" << i << ".0\n";
		}
	}
	try {
		open("kitti", dir.path());
		FAIL() << "unequal left/right counts were accepted";
	} catch (const SourceError &e) {
		EXPECT_NE(std::string(e.what()).find("has 3 frames but image_03 has 2"), std::string::npos) << e.what();
	}
}

TEST(DatasetDefects, BadFolderTimestampNamesFileAndLine)
{
	// It used to say only "stereod: stoll".
	TempDir dir;
	for (int i = 0; i < 2; ++i) {
		write_image(dir.path() / "left" / ("l" + std::to_string(i) + ".png"), i);
		write_image(dir.path() / "right" / ("r" + std::to_string(i) + ".png"), i);
	}
	std::ofstream(dir.path() / "timestamps.txt") << "5.0\nsoon\n";
	try {
		datasets::folder_pair(dir.path().string(), 10.0);
		FAIL() << "a non-numeric timestamp was accepted";
	} catch (const SourceError &e) {
		EXPECT_NE(std::string(e.what()).find("timestamps.txt:2: not a time in seconds: 'soon'"),
			  std::string::npos)
			<< e.what();
	}
}
