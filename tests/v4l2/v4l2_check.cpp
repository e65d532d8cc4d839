// v4l2_check: stereod's V4L2 driver (the same V4l2Source the daemon runs, through the same FrameSource
// interface) against real kernel drivers. Runs inside the QEMU test bed, where the daemon's full set of
// libraries (OpenCV's codecs, GDAL, FFmpeg: ~280 MB) would not fit a quick initramfs.
//
//   v4l2_check --set v4l2.left=/dev/video0 --set v4l2.right=/dev/video1 ... --frames 60 [--pattern]
// Prints one "V4L2CHECK" line with frames, fps, sequence gaps, skew and the status counters; exits non-zero
// when the frames did not come, or (--pattern) when any pixel differs from what v4l2_feed wrote.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/clock.hpp"
#include "drivers/builtin.hpp"
#include "tests/v4l2/pattern.hpp"

using namespace stereod;

namespace {

void set(drivers::V4l2Config &c, const std::string &assignment)
{
	const auto eq = assignment.find('=');
	const std::string key = assignment.substr(0, eq), value = assignment.substr(eq + 1);
	if (key == "v4l2.left")
		c.left = value;
	else if (key == "v4l2.right")
		c.right = value;
	else if (key == "v4l2.layout")
		c.layout = value;
	else if (key == "v4l2.width")
		c.width = std::atoi(value.c_str());
	else if (key == "v4l2.height")
		c.height = std::atoi(value.c_str());
	else if (key == "v4l2.pixel_format")
		c.pixel_format = value;
	else if (key == "v4l2.fps")
		c.fps = std::atof(value.c_str());
	else if (key == "v4l2.max_skew_ms")
		c.max_skew_ms = std::atof(value.c_str());
	else if (key == "v4l2.color")
		c.color = value;
	else {
		std::fprintf(stderr, "v4l2_check: unknown setting %s\n", key.c_str());
		std::exit(2);
	}
}

} // namespace

int main(int argc, char **argv)
{
	drivers::SourceConfig config;
	config.driver = "v4l2";
	int frames = 60;
	bool pattern = false;
	for (int i = 1; i < argc; ++i) {
		const std::string arg = argv[i];
		if (arg == "--set" && i + 1 < argc)
			set(config.v4l2, argv[++i]);
		else if (arg == "--frames" && i + 1 < argc)
			frames = std::atoi(argv[++i]);
		else if (arg == "--pattern")
			pattern = true;
	}
	drivers::SourceRegistry registry;
	drivers::register_v4l2(registry);
	std::unique_ptr<drivers::FrameSource> source;
	try {
		source = registry.create(config);
	} catch (const std::exception &e) {
		std::printf("V4L2CHECK FAIL open: %s\n", e.what());
		return 1;
	}
	const auto &info = source->info();
	StereoFrame frame;
	frame.allocate(info.geometry);
	int got = 0, timeouts = 0, bad_pixels = 0, not_ok = 0;
	uint64_t last_seq = 0, gaps = 0;
	int64_t first_t = 0, last_t = 0, max_skew = 0;
	bool monotonic = true;
	while (got < frames && timeouts < 50) {
		const auto status = source->grab(frame);
		if (status != drivers::GrabStatus::Frame) {
			if (status == drivers::GrabStatus::Lost) {
				std::printf("V4L2CHECK FAIL device lost\n");
				return 1;
			}
			++timeouts;
			continue;
		}
		if (got == 0) {
			first_t = frame.device_ns;
		} else {
			gaps += frame.sequence - last_seq - 1;
			monotonic = monotonic && frame.device_ns > last_t;
		}
		last_seq = frame.sequence;
		last_t = frame.device_ns;
		max_skew = std::max<int64_t>(max_skew, std::llabs(frame.lr_skew_ns));
		if (frame.status != FrameStatus::Ok)
			++not_ok;
		if (pattern)
			bad_pixels += v4l2test::count_mismatches(frame.left, frame.right);
		++got;
	}
	const double span = static_cast<double>(last_t - first_t) * 1e-9;
	const auto counters = source->counters();
	std::printf(
		"V4L2CHECK %s frames=%d eye=%dx%d fps=%.2f seq_gaps=%llu monotonic=%d max_skew_ms=%.2f not_ok=%d "
		"bad_pixels=%d unpaired=%llu (%s)\n",
		got == frames && monotonic && (!pattern || bad_pixels == 0) ? "ok" : "FAIL", got, info.geometry.width,
		info.geometry.height, got > 1 && span > 0 ? (got - 1) / span : 0.0,
		static_cast<unsigned long long>(gaps), monotonic ? 1 : 0, static_cast<double>(max_skew) * 1e-6, not_ok,
		bad_pixels,
		static_cast<unsigned long long>(counters.drops.count("unpaired") ? counters.drops.at("unpaired") : 0),
		info.description.c_str());
	return got == frames && monotonic && (!pattern || bad_pixels == 0) ? 0 : 1;
}
