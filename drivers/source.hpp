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

struct SourceConfig {
	std::string driver = "sim"; ///< a name in the SourceRegistry
	std::string path;	    ///< file or folder for the file-backed drivers
	ReplayRate rate = ReplayRate::Fast;
	bool realtime = true; ///< live pacing for sources that are not files (sim)
	double fps = 0;	      ///< overrides the frame rate where the input has none (folder pairs)
	SimConfig sim;
};

/// Rectified pinhole stereo calibration, where the source knows it (sim, KITTI's calib files).
struct StereoCalibration {
	double fx = 0, fy = 0, cx = 0, cy = 0; ///< left camera, pixels
	double baseline_m = 0;		       ///< right camera's offset along the left camera's x axis
};

struct SourceInfo {
	std::string name;	 ///< driver name, e.g. "sim", "kitti"
	std::string description; ///< human-readable: what is being played
	FrameGeometry geometry;
	bool live = false;	  ///< frames arrive whether or not we take them (drop-oldest applies)
	uint64_t frame_count = 0; ///< known length of a finite source, 0 if unknown
	std::optional<StereoCalibration> calibration;
};

class FrameSource
{
public:
	virtual ~FrameSource() = default;
	[[nodiscard]] virtual const SourceInfo &info() const = 0;
	/// Fills `into` (allocated at info().geometry) in place. Must not allocate in steady state.
	virtual GrabStatus grab(StereoFrame &into) = 0;
	/// After Lost: tries to get the device back; true when grabbing may resume.
	virtual bool reconnect() { return false; }
	/// Notes for the user after the end of a file source (e.g. what a damaged recording lost).
	[[nodiscard]] virtual std::vector<std::string> report() const { return {}; }
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
