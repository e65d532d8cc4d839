// Sources over dataset layouts (kitti, euroc, tum, folder) and video files.
#include <spdlog/spdlog.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "core/clock.hpp"
#include "drivers/builtin.hpp"
#include "drivers/replay/datasets.hpp"
#include "drivers/replay/pacer.hpp"

namespace stereod::drivers {
namespace {

/// Decodes `file` into the preallocated `target`, converting colour to the target's format. False if the
/// file is unreadable or has the wrong size (the frame is then marked corrupt, the stream goes on).
bool load_into(const std::string &file, cv::Mat &target, cv::Mat &decoded)
{
	decoded = cv::imread(file, target.channels() == 1 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
	if (decoded.empty() || decoded.size() != target.size())
		return false;
	decoded.copyTo(target);
	return true;
}

class IndexSource final : public FrameSource
{
public:
	IndexSource(std::string name, datasets::Index index, const SourceConfig &config)
		: index_(std::move(index)), pacer_(config.rate)
	{
		if (index_.entries.empty())
			throw SourceError(name + ": no frames found in " + config.path);
		for (const auto &note : index_.notes)
			spdlog::warn("{}", note);
		const Entry &first = index_.entries.front();
		cv::Mat probe = cv::imread(first.left, cv::IMREAD_UNCHANGED);
		if (probe.empty())
			throw SourceError(name + ": cannot read the first image " + first.left);
		info_.name = std::move(name);
		info_.description = config.path;
		info_.geometry.width = probe.cols;
		info_.geometry.height = probe.rows;
		info_.geometry.format = probe.channels() == 1 ? PixelFormat::Mono8 : PixelFormat::Bgr8;
		info_.geometry.stereo = !first.right.empty();
		info_.geometry.depth = !first.depth.empty();
		if (index_.entries.size() > 1) {
			const double span_s =
				static_cast<double>(index_.entries.back().device_ns - first.device_ns) * 1e-9;
			info_.geometry.nominal_fps =
				span_s > 0 ? static_cast<double>(index_.entries.size() - 1) / span_s : 0;
		}
		info_.live = false;
		info_.frame_count = index_.entries.size();
		info_.calibration = index_.calibration;
	}

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		if (next_ >= index_.entries.size())
			return GrabStatus::EndOfStream;
		const Entry &entry = index_.entries[next_];
		if (!pacer_.wait_for(entry.device_ns))
			return GrabStatus::EndOfStream;
		bool ok = load_into(entry.left, into.left, decoded_);
		if (info_.geometry.stereo)
			ok = load_into(entry.right, into.right, decoded_) && ok;
		if (info_.geometry.depth) {
			decoded_ = cv::imread(entry.depth, cv::IMREAD_ANYDEPTH);
			if (decoded_.empty() || decoded_.size() != into.depth.size() || decoded_.depth() != CV_16U)
				ok = false;
			else
				decoded_.convertTo(into.depth, CV_32F, 1.0 / index_.depth_scale);
		}
		if (!ok) {
			++corrupt_;
			spdlog::warn("{}: frame {} ({}) is unreadable or has the wrong size; marked corrupt",
				     info_.name, next_, entry.left);
		}
		into.sequence = next_++;
		into.device_ns = entry.device_ns;
		into.lr_skew_ns = entry.lr_skew_ns;
		into.host_ns = monotonic_ns();
		into.status = ok ? FrameStatus::Ok : FrameStatus::Corrupt;
		return GrabStatus::Frame;
	}

	std::vector<std::string> report() const override
	{
		std::vector<std::string> lines = index_.notes;
		lines.push_back(info_.name + ": " + std::to_string(next_) + " frames read, " +
				std::to_string(corrupt_) + " corrupt");
		return lines;
	}

private:
	using Entry = datasets::Entry;
	datasets::Index index_;
	Pacer pacer_;
	SourceInfo info_;
	size_t next_ = 0;
	uint64_t corrupt_ = 0;
	cv::Mat decoded_;
};

class VideoSource final : public FrameSource
{
public:
	explicit VideoSource(const SourceConfig &config) : pacer_(config.rate)
	{
		if (!capture_.open(config.path) || !capture_.isOpened())
			throw SourceError("video: cannot open " + config.path);
		if (!capture_.read(first_) || first_.empty())
			throw SourceError("video: " + config.path + " has no readable frame");
		double fps = capture_.get(cv::CAP_PROP_FPS);
		if (config.fps > 0)
			fps = config.fps;
		if (!(fps > 0 && fps < 10000))
			throw SourceError("video: " + config.path + " states no frame rate; set source.fps");
		fps_ = fps;
		info_.name = "video";
		info_.description = config.path;
		info_.geometry = {
			first_.cols, first_.rows, first_.channels() == 1 ? PixelFormat::Mono8 : PixelFormat::Bgr8,
			false,	     false,	  false,
			fps};
		info_.live = false;
		const double count = capture_.get(cv::CAP_PROP_FRAME_COUNT);
		info_.frame_count = count > 0 ? static_cast<uint64_t>(count) : 0;
	}

	const SourceInfo &info() const override { return info_; }

	GrabStatus grab(StereoFrame &into) override
	{
		if (have_first_) {
			have_first_ = false;
			first_.copyTo(into.left);
		} else if (!capture_.read(into.left) || into.left.empty()) {
			return GrabStatus::EndOfStream;
		}
		// The frame index at the container's constant rate: decoders' own position stamps are not
		// reliable across codecs, the rate is.
		const auto device_ns = static_cast<int64_t>(std::llround(static_cast<double>(next_) * 1e9 / fps_));
		if (!pacer_.wait_for(device_ns))
			return GrabStatus::EndOfStream;
		into.sequence = next_++;
		into.device_ns = device_ns;
		into.host_ns = monotonic_ns();
		into.status = FrameStatus::Ok;
		return GrabStatus::Frame;
	}

	std::vector<std::string> report() const override
	{
		return {"video: " + std::to_string(next_) + " frames decoded"};
	}

private:
	cv::VideoCapture capture_;
	cv::Mat first_;
	bool have_first_ = true;
	double fps_ = 0;
	Pacer pacer_;
	SourceInfo info_;
	uint64_t next_ = 0;
};

} // namespace

void register_datasets(SourceRegistry &registry)
{
	registry.add("video", "a video file (monocular)",
		     [](const SourceConfig &c) { return std::make_unique<VideoSource>(c); });
	registry.add("kitti", "KITTI raw drive folder (image_02, image_03)", [](const SourceConfig &c) {
		return std::make_unique<IndexSource>("kitti", datasets::kitti(c.path), c);
	});
	registry.add("euroc", "EuRoC/ASL sequence (mav0/cam0, mav0/cam1)", [](const SourceConfig &c) {
		return std::make_unique<IndexSource>("euroc", datasets::euroc(c.path), c);
	});
	registry.add("tum", "TUM RGB-D sequence (rgb.txt, depth.txt)", [](const SourceConfig &c) {
		return std::make_unique<IndexSource>("tum", datasets::tum(c.path), c);
	});
	registry.add("folder", "a folder with left/ and right/ images", [](const SourceConfig &c) {
		return std::make_unique<IndexSource>("folder", datasets::folder_pair(c.path, c.fps > 0 ? c.fps : 10.0),
						     c);
	});
}

} // namespace stereod::drivers
