// A GigE Vision camera for tests: Aravis's own fake camera protocol stack (ArvGvFakeCamera) serving real
// pictures instead of its diagonal ramp, so a test can check every byte end to end.
//
//   stereod_fakecam ADDRESS SERIAL --ramp                       a diagonal ramp moving one grey level per
//                                                               frame (Aravis's own pattern), no file needed
//   stereod_fakecam ADDRESS SERIAL --image eye.png              Mono8: the picture, grey
//   stereod_fakecam --write-grey in.jpg out.png                 the grey picture as served, for comparisons
//   stereod_fakecam ADDRESS SERIAL --interleave left.png right.png [--first right|left]
//                                                               Mono16: both eyes in alternate bytes, as a
//                                                               Point Grey Bumblebee sends them
// The picture is tiled to whatever Width x Height the client sets. SIGINT/SIGTERM stop it. Only ever bind
// it to an address inside a network namespace the test made (discovery answers on every interface).
//
// Timestamps: Aravis's fake camera stamps a frame with the host's real time when its sending thread gets
// round to filling it, so a thread woken 15 ms late (a busy 2-core machine) sends a frame stamped 15 ms
// late. A real camera stamps the exposure from its own clock, whatever its sender does afterwards. This one
// does that: a frame is stamped with the frame-period slot it was due in (the fake's cadence is a grid of
// the period on the real-time clock), and its frame id counts slots.
// A camera's sensor also exposes on time while the link is busy, and keeps the frames in its memory until
// they are sent. When this machine stalls the sending thread past a slot (the fakes share two cores with the
// daemon and the test), the slots it missed are sent as soon as it runs again, back to back, each stamped
// with its own slot -- up to kFrameMemory frames, as a camera with that much memory would. Past that the
// frames are lost and their ids missing, as on a camera whose memory overflowed.
#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <poll.h>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#pragma GCC diagnostic ignored "-Wold-style-cast" // GLib and Aravis macros
#include <arv.h>
#include <glib-unix.h>

// Aravis 0.8's fake camera thread (arvgvfakecamera.c, also upstream today) computes its poll timeout as
// `(next_timestamp_us - g_get_real_time ()) / 1000` with next_timestamp_us unsigned: when the clock passes the
// frame's due time between the loop's test and that line (the thread spins on poll(0) in the last
// millisecond), the difference wraps, the timeout is clamped to 100 ms and three frame slots are lost.
// libaravis calls g_poll through the PLT, so this definition is the one it gets: the thread's waits are cut
// to 2 ms, after which it sees the due time has passed and sends. A wait the thread meant to be longer just
// goes round its loop again (it re-tests the time), so nothing else changes.
extern "C" gint g_poll(GPollFD *fds, guint nfds, gint timeout)
{
	static_assert(sizeof(GPollFD) == sizeof(pollfd), "GPollFD is struct pollfd on Linux");
	return poll(reinterpret_cast<pollfd *>(fds), nfds, timeout < 0 ? timeout : std::min(timeout, 2));
}

namespace {

constexpr guint64 kFrameMemory = 8; ///< frames a late sender may still send (6 MB at 1024x768 Mono8)

/// What the sending thread knows of its cadence; only ever touched on that thread.
struct SenderCadence {
	guint64 period_us = 0; ///< 0 until the thread has sent its first frame
	guint64 last_slot = 0;
	bool after_fill = false; ///< the next clock reading is the one the thread plans its next frame by
};
thread_local SenderCadence sender;

gint64 real_time_us()
{
	timespec now{};
	clock_gettime(CLOCK_REALTIME, &now);
	return static_cast<gint64>(now.tv_sec) * 1000000 + now.tv_nsec / 1000;
}

} // namespace

// The fake camera's thread plans its next frame as "the next slot boundary after the time now" (its first
// clock reading after sending a frame). A thread that is behind is shown the moment just before the slot it
// owes, so it sends that frame at once; libaravis calls g_get_real_time through the PLT and gets this one.
// Any other thread, or any other reading, gets the real time.
extern "C" gint64 g_get_real_time()
{
	const gint64 now = real_time_us();
	if (!sender.after_fill)
		return now;
	sender.after_fill = false;
	const auto due = static_cast<gint64>((sender.last_slot + 1) * sender.period_us);
	const auto memory_end = static_cast<gint64>((sender.last_slot + kFrameMemory) * sender.period_us);
	return now >= due && now < memory_end ? due - 1 : now;
}

namespace {

struct Pictures {
	cv::Mat first;	///< Mono8, or byte 0 of each Mono16 pixel
	cv::Mat second; ///< empty, or byte 1 of each Mono16 pixel
	bool ramp = false;
	std::vector<unsigned char> ramp_line;
	guint64 sent_late = 0; ///< frames sent after their slot had passed (reported at exit)
	ArvFakeCamera *camera = nullptr;
	guint64 first_slot = 0; ///< the slot of the first frame sent, for frame ids counted in slots
};

/// The exposure time stamp and frame id of the frame being filled (see the file comment).
void stamp_on_slot(ArvBuffer *buffer, Pictures &pictures)
{
	guint32 period_us = 0;
	arv_fake_camera_read_register(pictures.camera, ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US,
				      &period_us);
	if (period_us == 0)
		return;
	// The sender wakes at or after its slot; the slot is the last grid point not after now, or the oldest
	// one it still owes when it runs late (see g_get_real_time above).
	const guint64 now_slot = static_cast<guint64>(real_time_us()) / period_us;
	guint64 slot = now_slot;
	const guint64 last = sender.period_us == period_us ? sender.last_slot : 0;
	if (last != 0 && now_slot > last + 1) {
		if (now_slot < last + kFrameMemory) {
			slot = last + 1;
			++pictures.sent_late;
		} else {
			std::fprintf(stderr, "stereod_fakecam: frame memory overflowed, %llu frame slot(s) lost\n",
				     static_cast<unsigned long long>(now_slot - last - 1));
		}
	} else if (last != 0 && now_slot <= last) {
		slot = last + 1; // never two frames for one slot
	}
	if (pictures.first_slot == 0 || slot < pictures.first_slot)
		pictures.first_slot = slot;
	sender = {period_us, slot, true};
	arv_buffer_set_timestamp(buffer, slot * period_us * 1000);
	// GVSP block ids are 16 bit and never 0; start where Aravis's fake starts (65400) to cross the wrap.
	const guint64 count = 65400 + (slot - pictures.first_slot);
	arv_buffer_set_frame_id(buffer, count % 65535 + 1);
}

/// Called by the fake camera's streaming thread for every frame.
void fill(ArvBuffer *buffer, void *data, guint32, guint32, ArvPixelFormat format)
{
	auto &pictures = *static_cast<Pictures *>(data);
	stamp_on_slot(buffer, pictures);
	auto *out = static_cast<unsigned char *>(const_cast<void *>(arv_buffer_get_data(buffer, nullptr)));
	const int w = arv_buffer_get_image_width(buffer), h = arv_buffer_get_image_height(buffer);
	// arv_buffer_get_data's size is the received size (0 on the sending side): work from the geometry.
	const size_t bytes = static_cast<size_t>(ARV_PIXEL_FORMAT_BIT_PER_PIXEL(format) / 8);
	if (pictures.ramp && bytes == 1) {
		// Row y of the ramp is the line (i % 255) from y + shift on: one copy per row keeps the sender quick.
		const auto shift = static_cast<size_t>(arv_buffer_get_frame_id(buffer) % 255);
		const size_t span = static_cast<size_t>(w) + static_cast<size_t>(h) + 255;
		if (pictures.ramp_line.size() < span)
			for (size_t i = pictures.ramp_line.size(); i < span; ++i)
				pictures.ramp_line.push_back(static_cast<unsigned char>(i % 255));
		for (int y = 0; y < h; ++y)
			std::memcpy(out + static_cast<size_t>(y) * static_cast<size_t>(w),
				    pictures.ramp_line.data() + static_cast<size_t>(y) + shift, static_cast<size_t>(w));
		return;
	}
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
	if (argc < 4 || (argc < 5 && std::string(argv[3]) != "--ramp")) {
		std::fprintf(stderr,
			     "usage: %s ADDRESS SERIAL --ramp | --image eye.png | --interleave left.png right.png "
			     "[--first right|left]\n",
			     argv[0]);
		return 2;
	}
	Pictures pictures;
	if (std::string(argv[3]) == "--ramp") {
		pictures.ramp = true;
		pictures.first = cv::Mat(1, 1, CV_8UC1); // for the size printed below
	} else if (std::string(argv[3]) == "--image") {
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
	pictures.camera = arv_gv_fake_camera_get_fake_camera(camera);
	arv_fake_camera_set_fill_pattern(pictures.camera, fill, &pictures);
	std::printf("stereod_fakecam: %s serving %dx%d as %s\n", argv[2], pictures.first.cols, pictures.first.rows,
		    argv[1]);
	std::fflush(stdout);
	GMainLoop *loop = g_main_loop_new(nullptr, FALSE);
	g_unix_signal_add(SIGINT, quit, loop);
	g_unix_signal_add(SIGTERM, quit, loop);
	g_main_loop_run(loop);
	g_object_unref(camera);
	g_main_loop_unref(loop);
	std::printf("stereod_fakecam: %llu frames sent late from frame memory\n",
		    static_cast<unsigned long long>(pictures.sent_late));
	return 0;
}
