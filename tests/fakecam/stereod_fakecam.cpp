// A GigE Vision camera for tests: Aravis's own fake camera protocol stack (ArvGvFakeCamera) serving real
// pictures instead of its diagonal ramp, so a test can check every byte end to end.
//
//   stereod_fakecam ADDRESS SERIAL --image eye.png              Mono8: the picture, grey
//   stereod_fakecam --write-grey in.jpg out.png                 the grey picture as served, for comparisons
//   stereod_fakecam ADDRESS SERIAL --interleave left.png right.png [--first right|left]
//                                                               Mono16: both eyes in alternate bytes, as a
//                                                               Point Grey Bumblebee sends them
// The picture is tiled to whatever Width x Height the client sets. SIGINT/SIGTERM stop it. Only ever bind
// it to an address inside a network namespace the test made (discovery answers on every interface).
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>

#include <opencv2/imgcodecs.hpp>

#pragma GCC diagnostic ignored "-Wold-style-cast" // GLib and Aravis macros
#include <arv.h>
#include <glib-unix.h>

namespace {

struct Pictures {
	cv::Mat first;	///< Mono8, or byte 0 of each Mono16 pixel
	cv::Mat second; ///< empty, or byte 1 of each Mono16 pixel
};

/// Called by the fake camera's streaming thread for every frame.
void fill(ArvBuffer *buffer, void *data, guint32, guint32, ArvPixelFormat format)
{
	const auto &pictures = *static_cast<const Pictures *>(data);
	auto *out = static_cast<unsigned char *>(const_cast<void *>(arv_buffer_get_data(buffer, nullptr)));
	const int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
	// arv_buffer_get_data's size is the received size (0 on the sending side): work from the geometry.
	const size_t bytes = static_cast<size_t>(ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format) / 8);
	const cv::Mat &a = pictures.first;
	for (int y = 0; y < h; ++y) {
		const unsigned char *row_a = a.ptr<unsigned char>(y % a.rows);
		const unsigned char *row_b =
			pictures.second.empty() ? row_a : pictures.second.ptr<unsigned char>(y % a.rows);
		unsigned char *o = out + static_cast<size_t>(y) * static_cast<size_t>(w) * bytes;
		for (int x = 0; x < w; ++x) {
			const int sx = x % a.cols;
			if (bytes == 2) {
				o[2 * x] = row_a[sx];
				o[2 * x + 1] = row_b[sx];
			} else if (bytes == 1) {
				o[x] = row_a[sx];
			} else {
				std::memset(o + static_cast<size_t>(x) * bytes, row_a[sx], bytes);
			}
		}
	}
}

gboolean quit(gpointer loop)
{
	g_main_loop_quit(static_cast<GMainLoop *>(loop));
	return G_SOURCE_REMOVE;
}

cv::Mat load(const char *path)
{
	cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
	if (image.empty()) {
		std::fprintf(stderr, "stereod_fakecam: cannot read %s\n", path);
		std::exit(2);
	}
	return image;
}

} // namespace

int main(int argc, char **argv)
{
	// --write-grey in.jpg out.png: the picture exactly as this camera serves it, for the test to compare with.
	if (argc == 4 && std::string(argv[1]) == "--write-grey")
		return cv::imwrite(argv[3], load(argv[2])) ? 0 : 1;
	if (argc < 5) {
		std::fprintf(stderr,
			     "usage: %s ADDRESS SERIAL --image eye.png | --interleave left.png right.png "
			     "[--first right|left]\n",
			     argv[0]);
		return 2;
	}
	Pictures pictures;
	if (std::string(argv[3]) == "--image") {
		pictures.first = load(argv[4]);
	} else if (std::string(argv[3]) == "--interleave" && argc >= 6) {
		const cv::Mat left = load(argv[4]), right = load(argv[5]);
		const bool first_right =
			!(argc >= 8 && std::string(argv[6]) == "--first" && std::string(argv[7]) == "left");
		pictures.first = first_right ? right : left;
		pictures.second = first_right ? left : right;
		if (left.size() != right.size()) {
			std::fprintf(stderr, "stereod_fakecam: the two pictures differ in size\n");
			return 2;
		}
	} else {
		std::fprintf(stderr, "stereod_fakecam: unknown mode %s\n", argv[3]);
		return 2;
	}
	ArvGvFakeCamera *camera = arv_gv_fake_camera_new_full(argv[1], argv[2], nullptr);
	if (!arv_gv_fake_camera_is_running(camera)) {
		std::fprintf(stderr, "stereod_fakecam: cannot start on %s (does an interface hold that address?)\n",
			     argv[1]);
		return 1;
	}
	arv_fake_camera_set_fill_pattern(arv_gv_fake_camera_get_fake_camera(camera), fill, &pictures);
	std::printf("stereod_fakecam: %s serving %dx%d as %s\n", argv[2], pictures.first.cols, pictures.first.rows,
		    argv[1]);
	std::fflush(stdout);
	GMainLoop *loop = g_main_loop_new(nullptr, FALSE);
	g_unix_signal_add(SIGINT, quit, loop);
	g_unix_signal_add(SIGTERM, quit, loop);
	g_main_loop_run(loop);
	g_object_unref(camera);
	g_main_loop_unref(loop);
	return 0;
}
