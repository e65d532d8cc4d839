#pragma once
// Every capture source -- simulated, replayed, or a real camera -- sits behind FrameSource and is created
// by name through the SourceRegistry.
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/frame.hpp"
#include "core/geometry/rig.hpp"

namespace stereod::drivers {

enum class GrabStatus : uint8_t {
	Frame,	     ///< `into` holds a new frame
	EndOfStream, ///< a finite source has nothing more
	Timeout,     ///< nothing arrived in time; try again
	Lost,	     ///< the device went away; call reconnect() (live sources) and try again
};

/// How a file-backed source paces its frames.
enum class ReplayRate : uint8_t {
	Recorded, ///< the recorded spacing of device timestamps
	Fast,	  ///< as fast as the consumer takes them
	Step,	  ///< one frame per line read from standard input
};

struct SimConfig {
	std::string scene = "default"; ///< default | static_near | static_far | moving_one | moving_many | toward
	uint64_t seed = 1;
	int width = 1024;
	int height = 768;
	double fps = 30;
	bool stereo = true;
	double baseline_m = 0.12;
	double noise_sigma = 2.0;	  ///< sensor noise, 8-bit units
	double blur_sigma = 0.6;	  ///< optical blur, pixels
	double exposure_variation = 0.06; ///< amplitude of the slow exposure/gain drift, fraction
	bool depth = false;		  ///< also emit true depth, as an RGB-D sensor would
	std::string texture_dir;	  ///< photographs for textures; empty = opencv-doc's sample images
	uint64_t frames = 0;		  ///< stop after this many frames; 0 = endless
};

/// GigE Vision / USB3 Vision cameras through Aravis ([aravis] in the config; docs/cameras.md).
struct AravisConfig {
	std::string left;	     ///< any id Aravis accepts: "Vendor-Model-Serial", an IP address, a user id
	std::string right;	     ///< empty: the left camera carries both eyes (see layout)
	std::string layout = "pair"; ///< pair | interleaved16 | side_by_side | top_bottom
	double frame_rate = 30.0;    ///< AcquisitionFrameRate; 0 = leave the camera's
	int width = 0;		     ///< 0 = leave the camera's
	int height = 0;		     ///< 0 = leave the camera's
	std::string pixel_format;    ///< GenICam name (Mono8, Mono16, BayerRG8, RGB8, ...); empty = leave
	double exposure_us = 0;	     ///< 0 = leave (auto exposure stays as configured on the camera)
	double gain_db = -1;	     ///< < 0 = leave
	int packet_size = 0;	     ///< GigE only: GevSCPSPacketSize; 0 = leave
	std::string trigger = "off"; ///< off | software (the daemon fires at frame_rate) | a TriggerSource name
	bool ptp = false;	     ///< enable IEEE 1588 on the cameras (GigE, where supported)
	std::string clock =
		"auto"; ///< auto | shared (the cameras' clocks are one: PTP) | per_camera; auto = shared with ptp
	double max_skew_ms =
		0; ///< pair: frames further apart are unpaired, counted, never mixed; 0 = a quarter of the frame period
	std::string first_byte = "right";  ///< interleaved16: which eye byte 0 of each pixel holds (Bumblebee: right)
	std::string bayer = "auto";	   ///< auto (from the pixel format) | none | RGGB | GRBG | GBRG | BGGR
	std::string color = "auto";	   ///< frame images: auto (bgr for colour sensors) | mono | bgr
	int buffers = 16;		   ///< stream buffers per camera, allocated once
	double no_frame_timeout_s = 3.0;   ///< no frame for this long: the camera is treated as lost
	std::vector<std::string> features; ///< further GenICam settings, "Name=value", applied last
};

/// Video4Linux2 devices ([v4l2]): UVC webcams, stereo UVC cameras, capture cards.
struct V4l2Config {
	std::string left = "/dev/video0";
	std::string right;		     ///< empty: one device carries both eyes (see layout)
	std::string layout = "side_by_side"; ///< pair | side_by_side | top_bottom
	int width = 0;			     ///< 0 = leave the driver's
	int height = 0;
	std::string pixel_format;   ///< YUYV | GREY | MJPG | ...; empty = leave the driver's
	double fps = 0;		    ///< VIDIOC_S_PARM; 0 = leave
	std::string color = "mono"; ///< frame images: mono | bgr
	int buffers = 4;	    ///< mmap buffers per device
	double max_skew_ms = 10.0;  ///< pair: frames further apart are unpaired
	double no_frame_timeout_s = 3.0;
	std::vector<std::string> controls; ///< "name=value" by the control's name (v4l2-ctl -l), e.g. "exposure_auto=1"
};

/// FireWire Point Grey Bumblebee2 / XB3 through libdc1394 ([dc1394]).
struct Dc1394Config {
	std::string guid;		  ///< hex GUID; empty: the first camera found
	std::string model = "bumblebee2"; ///< bumblebee2 | xb3
	std::string sensors = "wide";	  ///< xb3: wide (outer pair) | narrow (left and middle)
	std::string first_byte = "right";
	std::string bayer = "auto"; ///< auto (from the camera's BAYER_TILE_MAPPING register) | none | RGGB | ...
	std::string color = "auto";
	double frame_rate = 0; ///< 0 = the camera's
};

struct SourceConfig {
	std::string driver = "sim"; ///< a name in the SourceRegistry
	std::string path;	    ///< file or folder for the file-backed drivers
	ReplayRate rate = ReplayRate::Fast;
	bool realtime = true; ///< live pacing for sources that are not files (sim)
	double fps = 0;	      ///< overrides the frame rate where the input has none (folder pairs)
	SimConfig sim;
	AravisConfig aravis;
	V4l2Config v4l2;
	Dc1394Config dc1394;
};

/// Rectified pinhole stereo calibration, where the source knows it (sim, KITTI's calib files).
using StereoCalibration = geometry::StereoRig;

struct SourceInfo {
	std::string name;	 ///< driver name, e.g. "sim", "kitti"
	std::string description; ///< human-readable: what is being played
	FrameGeometry geometry;
	bool live = false;	  ///< frames arrive whether or not we take them (drop-oldest applies)
	uint64_t frame_count = 0; ///< known length of a finite source, 0 if unknown
	std::optional<StereoCalibration> calibration;
};

struct SourceCounters {
	std::map<std::string, uint64_t> drops;
	std::map<std::string, int64_t> device;
};

class FrameSource
{
public:
	virtual ~FrameSource() = default;
	[[nodiscard]] virtual const SourceInfo &info() const = 0;
	/// Fills `into` (allocated at info().geometry) in place. Must not allocate in steady state
	/// (tests/alloc counts it for the cameras' paths and replay; the sim's OpenCV warps and the image-folder
	/// datasets' decoders allocate inside OpenCV).
	virtual GrabStatus grab(StereoFrame &into) = 0;
	/// After Lost: tries to get the device back; true when grabbing may resume.
	virtual bool reconnect() { return false; }
	/// Notes for the user after the end of a file source (e.g. what a damaged recording lost).
	[[nodiscard]] virtual std::vector<std::string> report() const { return {}; }
	/// The source's own counters for `status`: `drops` are frames lost inside the source (unpaired,
	/// failed buffers, an outage), `device` the transport's statistics (completed buffers, missing packets,
	/// skew). Thread-safe: called from the status thread while the capture thread grabs.
	[[nodiscard]] virtual SourceCounters counters() const { return {}; }
};

/// Errors a source gives when it cannot be opened: a message naming what is wrong with which path.
class SourceError : public std::runtime_error
{
public:
	using std::runtime_error::runtime_error;
};

class SourceRegistry
{
public:
	using Factory = std::function<std::unique_ptr<FrameSource>(const SourceConfig &)>;

	/// The registry with every driver this build has.
	static SourceRegistry with_builtin_drivers();

	void add(std::string name, std::string summary, Factory factory);
	/// Throws SourceError for an unknown name (listing the known ones) or a source that cannot open.
	[[nodiscard]] std::unique_ptr<FrameSource> create(const SourceConfig &config) const;
	[[nodiscard]] std::vector<std::string> names() const;
	[[nodiscard]] const std::string &summary(const std::string &name) const;

private:
	struct Entry {
		std::string summary;
		Factory factory;
	};
	std::map<std::string, Entry> entries_;
};

} // namespace stereod::drivers
