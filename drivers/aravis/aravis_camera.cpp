#include "drivers/aravis/aravis_camera.hpp"

#include <sstream>
#include <time.h>

#include <spdlog/spdlog.h>

#include "core/clock.hpp"

// Aravis's and GLib's macros (ARV_GV_STREAM, pixel format constants, ...) are C casts.
#pragma GCC diagnostic ignored "-Wold-style-cast"
#include <arv.h>

namespace stereod::drivers::aravis {
namespace {

/// Owns a GError; throws SourceError with the context and the library's message.
struct Error {
	GError *error = nullptr;
	~Error() { g_clear_error(&error); }
	GError **operator&() noexcept { return &error; }
	explicit operator bool() const noexcept { return error != nullptr; }
	[[nodiscard]] std::string message() const { return error ? error->message : ""; }
	void check(const std::string &context)
	{
		if (error) {
			const std::string text = context + ": " + message();
			g_clear_error(&error);
			throw SourceError(text);
		}
	}
};

std::string join(const char **items, guint n)
{
	std::string out;
	for (guint i = 0; i < n; ++i)
		out += (i ? ", " : "") + std::string(items[i]);
	return out;
}

template <typename T>
std::string range_text(T lo, T hi)
{
	std::ostringstream out;
	out << lo << ".." << hi;
	return out.str();
}

void on_control_lost(ArvDevice *, gpointer flag)
{
	static_cast<std::atomic<bool> *>(flag)->store(true);
}

} // namespace

std::string found_cameras_text()
{
	arv_update_device_list();
	const unsigned n = arv_get_n_devices();
	if (n == 0)
		return "no camera was found (GigE cameras must be on a reachable subnet; USB3 Vision cameras need "
		       "access to the USB device)";
	std::string out = "cameras found: ";
	for (unsigned i = 0; i < n; ++i) {
		const char *address = arv_get_device_address(i);
		out += (i ? ", " : "") + std::string(arv_get_device_id(i)) +
		       (address && *address ? " (" + std::string(address) + ")" : "");
	}
	return out;
}

AravisCamera::AravisCamera(const std::string &id, const AravisConfig &config, const std::string &role)
	: id_(id), role_(role)
{
	Error error;
	camera_ = arv_camera_new(id.c_str(), &error);
	if (!camera_)
		throw SourceError("aravis." + role + " = \"" + id + "\": cannot open the camera (" + error.message() +
				  "); " + found_cameras_text());
	try {
		gige_ = arv_camera_is_gv_device(camera_);
		lost_handler_ = g_signal_connect_data(arv_camera_get_device(camera_), "control-lost",
						      reinterpret_cast<GCallback>(on_control_lost), &control_lost_,
						      nullptr, GConnectFlags{});
		configure(config);
	} catch (...) {
		close();
		throw;
	}
}

AravisCamera::~AravisCamera()
{
	close();
}

void AravisCamera::close() noexcept
{
	if (camera_ && acquiring_)
		arv_camera_stop_acquisition(camera_, nullptr);
	acquiring_ = false;
	if (stream_)
		g_object_unref(stream_); // frees every buffer the stream still holds
	stream_ = nullptr;
	if (camera_) {
		if (lost_handler_)
			g_signal_handler_disconnect(arv_camera_get_device(camera_), lost_handler_);
		g_object_unref(camera_);
	}
	camera_ = nullptr;
}

void AravisCamera::configure(const AravisConfig &config)
{
	const std::string where = "aravis." + role_ + " (" + id_ + ")";
	Error error;
	arv_camera_stop_acquisition(camera_, nullptr); // a camera left streaming by a crashed process

	if (config.width > 0 || config.height > 0) {
		gint x = 0, y = 0, w = 0, h = 0;
		arv_camera_get_region(camera_, &x, &y, &w, &h, &error);
		error.check(where + ": reading the region");
		const int want_w = config.width > 0 ? config.width : w;
		const int want_h = config.height > 0 ? config.height : h;
		gint wmin = 0, wmax = 0, hmin = 0, hmax = 0;
		arv_camera_get_width_bounds(camera_, &wmin, &wmax, nullptr);
		arv_camera_get_height_bounds(camera_, &hmin, &hmax, nullptr);
		if (want_w < wmin || want_w > wmax || want_h < hmin || want_h > hmax)
			throw SourceError(where + ": Width x Height = " + std::to_string(want_w) + "x" +
					  std::to_string(want_h) + " is outside what the camera allows (Width " +
					  range_text(wmin, wmax) + ", Height " + range_text(hmin, hmax) + ")");
		arv_camera_set_region(camera_, 0, 0, want_w, want_h, &error);
		error.check(where + ": setting Width x Height = " + std::to_string(want_w) + "x" +
			    std::to_string(want_h));
	}
	if (!config.pixel_format.empty()) {
		guint n = 0;
		const char **formats = arv_camera_dup_available_pixel_formats_as_strings(camera_, &n, nullptr);
		bool known = false;
		for (guint i = 0; formats && i < n; ++i)
			known = known || config.pixel_format == formats[i];
		const std::string allowed = formats ? join(formats, n) : std::string("?");
		g_free(formats);
		if (!known)
			throw SourceError(where + ": PixelFormat = " + config.pixel_format +
					  " is not offered by the camera (it offers " + allowed + ")");
		arv_camera_set_pixel_format_from_string(camera_, config.pixel_format.c_str(), &error);
		error.check(where + ": setting PixelFormat = " + config.pixel_format + " (offered: " + allowed + ")");
	}
	if (config.frame_rate > 0) {
		double lo = 0, hi = 0;
		arv_camera_get_frame_rate_bounds(camera_, &lo, &hi, nullptr);
		if (config.frame_rate < lo || config.frame_rate > hi)
			throw SourceError(where + ": AcquisitionFrameRate = " + std::to_string(config.frame_rate) +
					  " is outside what the camera allows (" + range_text(lo, hi) + ")");
		arv_camera_set_frame_rate(camera_, config.frame_rate, &error);
		error.check(where + ": setting AcquisitionFrameRate = " + std::to_string(config.frame_rate));
	}
	if (config.exposure_us > 0) {
		double lo = 0, hi = 0;
		arv_camera_get_exposure_time_bounds(camera_, &lo, &hi, nullptr);
		if (config.exposure_us < lo || config.exposure_us > hi)
			throw SourceError(where + ": ExposureTime = " + std::to_string(config.exposure_us) +
					  " us is outside what the camera allows (" + range_text(lo, hi) + " us)");
		arv_camera_set_exposure_time(camera_, config.exposure_us, &error);
		error.check(where + ": setting ExposureTime = " + std::to_string(config.exposure_us));
	}
	if (config.gain_db >= 0) {
		if (!arv_camera_is_gain_available(camera_, nullptr))
			throw SourceError(where + ": the camera has no gain control (Gain / GainRaw)");
		double lo = 0, hi = 0;
		arv_camera_get_gain_bounds(camera_, &lo, &hi, nullptr);
		if (config.gain_db < lo || config.gain_db > hi)
			throw SourceError(where + ": Gain = " + std::to_string(config.gain_db) +
					  " is outside what the camera allows (" + range_text(lo, hi) + ")");
		arv_camera_set_gain(camera_, config.gain_db, &error);
		error.check(where + ": setting Gain = " + std::to_string(config.gain_db));
	}
	if (config.trigger == "off") {
		arv_camera_clear_triggers(camera_, nullptr); // cameras without triggers have nothing to clear
	} else {
		const std::string source = config.trigger == "software" ? "Software" : config.trigger;
		guint n = 0;
		const char **sources = arv_camera_dup_available_trigger_sources(camera_, &n, nullptr);
		const std::string allowed = sources ? join(sources, n) : std::string("none");
		g_free(sources);
		arv_camera_set_trigger(camera_, source.c_str(), &error);
		error.check(where + ": TriggerSource = " + source + " (the camera offers " + allowed + ")");
	}
	if (config.packet_size > 0) {
		if (!gige_)
			throw SourceError(where + ": packet_size applies to GigE Vision cameras only");
		arv_camera_gv_set_packet_size(camera_, config.packet_size, &error);
		error.check(where + ": GevSCPSPacketSize = " + std::to_string(config.packet_size));
		const unsigned actual = arv_camera_gv_get_packet_size(camera_, nullptr);
		if (static_cast<int>(actual) != config.packet_size)
			throw SourceError(where + ": GevSCPSPacketSize = " + std::to_string(config.packet_size) +
					  " was not taken (the camera kept " + std::to_string(actual) + ")");
	}
	if (config.ptp) {
		const char *feature = nullptr;
		for (const char *name : {"PtpEnable", "GevIEEE1588"})
			if (!feature && arv_camera_is_feature_available(camera_, name, nullptr))
				feature = name;
		if (!feature)
			throw SourceError(where + ": ptp = true, but the camera has neither PtpEnable nor GevIEEE1588");
		arv_camera_set_boolean(camera_, feature, TRUE, &error);
		error.check(where + ": setting " + std::string(feature) + " = true");
	}
	ArvDevice *device = arv_camera_get_device(camera_);
	for (const auto &setting : config.features) {
		const auto eq = setting.find('=');
		const std::string name = setting.substr(0, eq);
		if (eq == std::string::npos || name.empty())
			throw SourceError(where + ": aravis.features entry '" + setting + "' is not Name=value");
		if (!arv_device_get_feature(device, name.c_str()))
			throw SourceError(where + ": aravis.features: the camera has no feature '" + name + "'");
		arv_device_set_features_from_string(device, setting.c_str(), &error);
		error.check(where + ": aravis.features: " + setting);
	}

	gint x = 0, y = 0;
	arv_camera_get_region(camera_, &x, &y, &width_, &height_, &error);
	error.check(where + ": reading the region");
	pixel_format_ = static_cast<uint32_t>(arv_camera_get_pixel_format(camera_, &error));
	error.check(where + ": reading PixelFormat");
	const char *format_name = arv_camera_get_pixel_format_as_string(camera_, nullptr);
	pixel_format_name_ = format_name ? format_name : "?";
	const char *vendor = arv_camera_get_vendor_name(camera_, nullptr);
	const char *model = arv_camera_get_model_name(camera_, nullptr);
	description_ = std::string(vendor ? vendor : "?") + " " + (model ? model : "?") + " (" + id_ + ")";

	stream_ = arv_camera_create_stream(camera_, nullptr, nullptr, &error);
	error.check(where + ": creating the stream");
	const guint payload = arv_camera_get_payload(camera_, &error);
	error.check(where + ": reading the payload size");
	payload_ = payload;
	const int buffers = std::max(2, config.buffers);
	for (int i = 0; i < buffers; ++i)
		arv_stream_push_buffer(stream_, arv_buffer_new(payload, nullptr));
	buffers_ = buffers;
}

void AravisCamera::start()
{
	if (acquiring_)
		return;
	Error error;
	arv_camera_start_acquisition(camera_, &error);
	error.check("aravis: " + role_ + " camera " + id_ + ": starting acquisition");
	acquiring_ = true;
	spdlog::info("aravis: {} {}: {}x{} {} at {} fps, payload {} bytes, {} buffers", role_, description_, width_,
		     height_, pixel_format_name_, arv_camera_get_frame_rate(camera_, nullptr), payload_, buffers_);
}

bool AravisCamera::next(uint64_t timeout_us, BufferView &view)
{
	const int64_t deadline = monotonic_ns() + static_cast<int64_t>(timeout_us) * 1000;
	for (;;) {
		const int64_t left_us = (deadline - monotonic_ns()) / 1000;
		if (left_us <= 0)
			return false;
		ArvBuffer *buffer = arv_stream_timeout_pop_buffer(stream_, static_cast<guint64>(left_us));
		if (!buffer)
			return false;
		const ArvBufferStatus status = arv_buffer_get_status(buffer);
		if (status != ARV_BUFFER_STATUS_SUCCESS && status != ARV_BUFFER_STATUS_MISSING_PACKETS) {
			spdlog::trace("aravis: {}: buffer {} status {}", role_, arv_buffer_get_frame_id(buffer),
				      static_cast<int>(status));
			++failed_;
			arv_stream_push_buffer(stream_, buffer);
			continue;
		}
		view.buffer = buffer;
		size_t size = 0;
		view.data = static_cast<const uint8_t *>(arv_buffer_get_data(buffer, &size));
		view.size = size;
		view.width = arv_buffer_get_image_width(buffer);
		view.height = arv_buffer_get_image_height(buffer);
		view.pixel_format = static_cast<uint32_t>(arv_buffer_get_image_pixel_format(buffer));
		view.frame_id = arv_buffer_get_frame_id(buffer);
		view.device_ns = static_cast<int64_t>(arv_buffer_get_timestamp(buffer));
		// The system timestamp is CLOCK_REALTIME at completion; carry it onto CLOCK_MONOTONIC by its age,
		// which is exact unless the real-time clock is stepped in the microseconds between the two reads.
		const int64_t system_ns = static_cast<int64_t>(arv_buffer_get_system_timestamp(buffer));
		const int64_t now_mono = monotonic_ns();
		view.arrival_ns = system_ns > 0 ? now_mono - std::max<int64_t>(0, realtime_ns() - system_ns) : now_mono;
		view.complete = status == ARV_BUFFER_STATUS_SUCCESS;
		if (!view.complete && view.width == 0) {
			// A buffer with missing packets may carry no image description (its leader was lost); its data
			// is still the full payload at the geometry the stream was opened with.
			view.width = width_;
			view.height = height_;
			view.pixel_format = pixel_format_;
		}
		if (!view.complete)
			view.size = std::max(view.size, payload_); // the buffer holds the whole payload, holes and all
		return true;
	}
}

void AravisCamera::give_back(BufferView &view)
{
	if (view.buffer)
		arv_stream_push_buffer(stream_, view.buffer);
	view.buffer = nullptr;
}

void AravisCamera::drain()
{
	while (ArvBuffer *buffer = arv_stream_try_pop_buffer(stream_))
		arv_stream_push_buffer(stream_, buffer);
}

void AravisCamera::software_trigger()
{
	arv_camera_software_trigger(camera_, nullptr);
}

StreamStatistics AravisCamera::statistics() const
{
	StreamStatistics s;
	guint64 completed = 0, failures = 0, underruns = 0;
	arv_stream_get_statistics(stream_, &completed, &failures, &underruns);
	s.completed = completed;
	s.failures = failures;
	s.underruns = underruns;
	if (gige_) {
		guint64 resent = 0, missing = 0;
		arv_gv_stream_get_statistics(ARV_GV_STREAM(stream_), &resent, &missing);
		s.resent_packets = resent;
		s.missing_packets = missing;
	}
	return s;
}

std::vector<DeviceDescription> list_devices()
{
	arv_update_device_list();
	std::vector<DeviceDescription> out;
	const unsigned n = arv_get_n_devices();
	for (unsigned i = 0; i < n; ++i) {
		DeviceDescription d;
		auto text = [](const char *s) { return std::string(s ? s : ""); };
		d.id = text(arv_get_device_id(i));
		d.vendor = text(arv_get_device_vendor(i));
		d.model = text(arv_get_device_model(i));
		d.serial = text(arv_get_device_serial_nbr(i));
		d.transport = text(arv_get_device_protocol(i));
		d.address = text(arv_get_device_address(i));
		Error error;
		ArvCamera *camera = arv_camera_new(d.id.c_str(), &error);
		if (!camera) {
			d.error = error.message();
			out.push_back(std::move(d));
			continue;
		}
		guint formats = 0;
		const char **names = arv_camera_dup_available_pixel_formats_as_strings(camera, &formats, nullptr);
		for (guint k = 0; names && k < formats; ++k)
			d.pixel_formats.emplace_back(names[k]);
		g_free(names);
		gint lo = 0;
		arv_camera_get_width_bounds(camera, &lo, &d.max_width, nullptr);
		arv_camera_get_height_bounds(camera, &lo, &d.max_height, nullptr);
		if (arv_camera_is_frame_rate_available(camera, nullptr))
			arv_camera_get_frame_rate_bounds(camera, &d.min_fps, &d.max_fps, nullptr);
		g_object_unref(camera);
		out.push_back(std::move(d));
	}
	return out;
}

} // namespace stereod::drivers::aravis
