// v4l2_feed DEVICE WIDTH HEIGHT FRAMES FPS [MJPG]: writes side-by-side GREY frames (tests/v4l2/pattern.hpp) into
// a v4l2loopback device, as a UVC stereo camera would deliver them; with MJPG, the same picture as a JPEG (the
// compressed stream most UVC stereo cameras send at full resolution).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fcntl.h>
#include <linux/videodev2.h>
#include <string>
#include <sys/ioctl.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <turbojpeg.h>

#include "tests/v4l2/pattern.hpp"

int main(int argc, char **argv)
{
	if (argc != 6 && !(argc == 7 && std::string(argv[6]) == "MJPG")) {
		std::fprintf(stderr, "usage: v4l2_feed DEVICE WIDTH HEIGHT FRAMES FPS [MJPG]\n");
		return 2;
	}
	const bool jpeg = argc == 7;
	const int w = std::atoi(argv[2]), h = std::atoi(argv[3]), n = std::atoi(argv[4]);
	const double fps = std::atof(argv[5]);
	const int fd = ::open(argv[1], O_WRONLY);
	if (fd < 0) {
		std::perror(argv[1]);
		return 1;
	}
	v4l2_format format{};
	format.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
	format.fmt.pix.width = static_cast<uint32_t>(w);
	format.fmt.pix.height = static_cast<uint32_t>(h);
	std::vector<uint8_t> image(static_cast<size_t>(w * h));
	const int half = w / 2;
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x)
			image[static_cast<size_t>(y * w + x)] =
				stereod::v4l2test::pattern_value(x % half, y, x >= half);
	if (jpeg) {
		tjhandle encoder = tjInitCompress();
		unsigned char *compressed = nullptr;
		unsigned long size = 0;
		if (encoder == nullptr || tjCompress2(encoder, image.data(), w, w, h, TJPF_GRAY, &compressed, &size,
						      TJSAMP_GRAY, 100, 0) != 0) {
			std::fprintf(stderr, "JPEG encoding failed\n");
			return 1;
		}
		image.assign(compressed, compressed + size);
		tjFree(compressed);
		tjDestroy(encoder);
	}
	format.fmt.pix.pixelformat = jpeg ? V4L2_PIX_FMT_MJPEG : V4L2_PIX_FMT_GREY;
	format.fmt.pix.field = V4L2_FIELD_NONE;
	format.fmt.pix.bytesperline = jpeg ? 0 : static_cast<uint32_t>(w);
	format.fmt.pix.sizeimage = static_cast<uint32_t>(jpeg ? image.size() : static_cast<size_t>(w * h));
	if (::ioctl(fd, VIDIOC_S_FMT, &format) != 0) {
		std::perror("VIDIOC_S_FMT");
		return 1;
	}
	const auto period = std::chrono::duration<double>(1.0 / fps);
	auto next = std::chrono::steady_clock::now();
	for (int i = 0; i < n; ++i) {
		if (::write(fd, image.data(), image.size()) != static_cast<ssize_t>(image.size())) {
			std::perror("write");
			return 1;
		}
		next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
		std::this_thread::sleep_until(next);
	}
	::close(fd);
	return 0;
}
