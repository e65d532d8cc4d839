#include "drivers/sim/sim_scene.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/spdlog.h>

namespace stereod::drivers::sim {
namespace {

namespace fs = std::filesystem;

constexpr double kGroundY = 1.4; ///< camera height above the ground (y points down)
constexpr double kNearZ = 0.05;	 ///< near clipping plane

cv::Matx33d rotation_y(double a)
{
	return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
}

cv::Matx33d rotation_x(double a)
{
	return {1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a)};
}

/// Uniform in [lo, hi) from the generator's raw bits, so the scene is the same with any standard library.
double uniform(std::mt19937_64 &rng, double lo, double hi)
{
	return lo + (hi - lo) * static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
}

/// Photographs to texture the scene with, by role; a procedural texture when none can be found.
class TextureBank
{
public:
	TextureBank(const std::string &dir_override, std::mt19937_64 &rng) : rng_(rng)
	{
		std::vector<std::string> dirs =
			dir_override.empty() ? default_texture_dirs() : std::vector<std::string>{dir_override};
		for (const auto &dir : dirs) {
			std::error_code ec;
			if (!fs::is_directory(dir, ec))
				continue;
			dir_ = dir;
			break;
		}
		if (dir_.empty())
			spdlog::warn("sim: no photographs found (install opencv-doc or set sim.texture_dir); "
				     "using procedural textures");
	}

	[[nodiscard]] const std::string &dir() const { return dir_; }

	/// The first of `names` that loads, else a procedural texture.
	cv::Mat photo(std::initializer_list<const char *> names)
	{
		for (const char *name : names) {
			if (dir_.empty())
				break;
			cv::Mat image = cv::imread((fs::path(dir_) / name).string(), cv::IMREAD_COLOR);
			if (!image.empty())
				return image;
		}
		return procedural(512, 512);
	}

	cv::Mat procedural(int width, int height)
	{
		cv::Mat noise(height, width, CV_8UC3);
		cv::theRNG().state = rng_();
		cv::randu(noise, cv::Scalar::all(0), cv::Scalar::all(255));
		cv::Mat smooth;
		cv::GaussianBlur(noise, smooth, cv::Size(0, 0), 2.0);
		cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
		return smooth;
	}

private:
	std::mt19937_64 &rng_;
	std::string dir_;
};

/// A width x height texture tiled from photographs resized to the given height.
cv::Mat mosaic(const std::vector<cv::Mat> &photos, int width, int height)
{
	cv::Mat out(height, width, CV_8UC3);
	int x = 0;
	for (size_t i = 0; x < width; ++i) {
		const cv::Mat &photo = photos[i % photos.size()];
		cv::Mat resized;
		const int w = std::max(1, photo.cols * height / std::max(photo.rows, 1));
		cv::resize(photo, resized, cv::Size(w, height), 0, 0, cv::INTER_AREA);
		const int take = std::min(w, width - x);
		resized(cv::Rect(0, 0, take, height)).copyTo(out(cv::Rect(x, 0, take, height)));
		x += take;
	}
	return out;
}

/// A width x height texture of rows of photographs, each resized to tile_height (about their own height, so
/// near surfaces keep the photographs' fine detail instead of a blown-up copy); rows start at different
/// photographs so the pattern does not repeat in columns.
cv::Mat mosaic_grid(const std::vector<cv::Mat> &photos, int width, int height, int tile_height)
{
	cv::Mat out(height, width, CV_8UC3);
	size_t next = 0;
	for (int y = 0; y < height; y += tile_height) {
		const int h = std::min(tile_height, height - y);
		// Each row starts one photograph later and still uses every photograph.
		const auto start = static_cast<std::ptrdiff_t>(next % photos.size());
		std::vector<cv::Mat> rotated(photos.begin() + start, photos.end());
		rotated.insert(rotated.end(), photos.begin(), photos.begin() + start);
		const cv::Mat row = mosaic(rotated, width, tile_height);
		row(cv::Rect(0, 0, width, h)).copyTo(out(cv::Rect(0, y, width, h)));
		++next;
	}
	return out;
}

/// A crop of a photograph the size of the mover at px_per_m, taken at the photograph's own resolution
/// where it is large enough (upscaled only when it is not), so movers keep real fine texture.
cv::Mat mover_texture(const cv::Mat &photo, double width_m, double height_m, double px_per_m, std::mt19937_64 &rng)
{
	const int tw = static_cast<int>(width_m * px_per_m);
	const int th = static_cast<int>(height_m * px_per_m);
	cv::Mat source = photo;
	const double scale =
		std::max({1.0, static_cast<double>(th) / photo.rows, static_cast<double>(tw) / photo.cols});
	if (scale > 1.0)
		cv::resize(photo, source, cv::Size(), scale, scale, cv::INTER_CUBIC);
	// Of a few random crops keep the most detailed (largest mean gradient): a crop of plain sky would make
	// a mover no feature detector can see, which says nothing about the classifier.
	cv::Rect best;
	double best_energy = -1;
	for (int attempt = 0; attempt < 6; ++attempt) {
		const int x = static_cast<int>(uniform(rng, 0, std::max(1, source.cols - tw)));
		const int y = static_cast<int>(uniform(rng, 0, std::max(1, source.rows - th)));
		const cv::Rect crop(x, y, std::min(tw, source.cols), std::min(th, source.rows));
		cv::Mat grey, dx, dy;
		cv::cvtColor(source(crop), grey, cv::COLOR_BGR2GRAY);
		cv::Sobel(grey, dx, CV_32F, 1, 0);
		cv::Sobel(grey, dy, CV_32F, 0, 1);
		const double energy = cv::mean(cv::abs(dx))[0] + cv::mean(cv::abs(dy))[0];
		if (energy > best_energy) {
			best_energy = energy;
			best = crop;
		}
	}
	return source(best).clone();
}

/// Clips a convex polygon (camera coordinates) to z >= kNearZ. Fixed capacity: no allocation.
size_t clip_near(const std::array<cv::Vec3d, 4> &in, std::array<cv::Vec3d, 8> &out)
{
	size_t n = 0;
	for (size_t i = 0; i < in.size(); ++i) {
		const cv::Vec3d &a = in[i];
		const cv::Vec3d &b = in[(i + 1) % in.size()];
		const bool a_in = a[2] >= kNearZ, b_in = b[2] >= kNearZ;
		if (a_in)
			out[n++] = a;
		if (a_in != b_in) {
			const double s = (kNearZ - a[2]) / (b[2] - a[2]);
			out[n++] = a + s * (b - a);
		}
	}
	return n;
}

struct MoverSpec {
	double x, z, vx, vz, x_lo, x_hi, z_lo, z_hi, start_time, width = 0.6, height = 1.75;
};

} // namespace

std::vector<std::string> default_texture_dirs()
{
	return {"/usr/share/doc/opencv-doc/examples/data", "/usr/share/opencv4/samples/data"};
}

std::pair<cv::Vec3d, cv::Vec3d> Mover::state_at(double t) const
{
	const double tau = std::max(0.0, t - start_time_s);
	cv::Vec3d position = start, velocity_now = velocity;
	auto bounce = [&](int axis, cv::Vec2d bounds) {
		const double lo = bounds[0], hi = bounds[1];
		if (velocity[axis] == 0 || hi <= lo)
			return;
		const double span = hi - lo;
		double s = std::fmod(start[axis] - lo + velocity[axis] * tau, 2 * span);
		if (s < 0)
			s += 2 * span;
		if (s > span) {
			position[axis] = lo + 2 * span - s;
			velocity_now[axis] = -velocity[axis];
		} else {
			position[axis] = lo + s;
		}
	};
	bounce(0, x_bounds);
	bounce(2, z_bounds);
	return {position, velocity_now};
}

Scene::Scene(const SimConfig &config) : config_(config)
{
	if (config.width < 64 || config.height < 64)
		throw SourceError("sim: width and height must be at least 64");
	std::mt19937_64 rng(config.seed);
	intrinsics_.fx = intrinsics_.fy = 0.9 * config.width;
	intrinsics_.cx = (config.width - 1) / 2.0;
	intrinsics_.cy = (config.height - 1) / 2.0;

	if (config.scene == "walk")
		wall_z_ = 34;
	TextureBank bank(config.texture_dir, rng);
	texture_origin_ = bank.dir().empty() ? "procedural" : bank.dir();

	// The back wall: a mosaic of photographs of walls and buildings, 66 px per metre (about 1:1 at 14 m).
	{
		TexturedPlane wall;
		wall.width_m = 40;
		wall.height_m = 10;
		wall.origin = {-20, kGroundY - wall.height_m, wall_z_};
		wall.axis_u = {1, 0, 0};
		wall.axis_v = {0, 1, 0};
		wall.texture =
			mosaic({bank.photo({"graf1.png"}), bank.photo({"building.jpg"}), bank.photo({"home.jpg"}),
				bank.photo({"graf3.png"}), bank.photo({"leuvenA.jpg"})},
			       2640, 660);
		background_.push_back(std::move(wall));
	}
	// The ground: aerial photographs, 120 px per metre (the walk's street: photographs at 200 px per metre,
	// 8 m wide, so the pavement a few metres ahead still has real detail).
	if (config.scene == "walk") {
		TexturedPlane ground;
		ground.width_m = 8;
		ground.height_m = wall_z_ + 6;
		ground.origin = {-4, kGroundY, -6};
		ground.axis_u = {1, 0, 0};
		ground.axis_v = {0, 0, 1};
		ground.texture = mosaic_grid({bank.photo({"aero1.jpg"}), bank.photo({"aero3.jpg"}),
					      bank.photo({"board.jpg"}), bank.photo({"stuff.jpg"})},
					     static_cast<int>(ground.width_m * 200),
					     static_cast<int>(ground.height_m * 200), 400);
		background_.push_back(std::move(ground));
	} else {
		TexturedPlane ground;
		ground.width_m = 40;
		ground.height_m = wall_z_ - 0.3;
		ground.origin = {-20, kGroundY, 0.3};
		ground.axis_u = {1, 0, 0};
		ground.axis_v = {0, 0, 1};
		ground.texture =
			mosaic({bank.photo({"aero1.jpg"}), bank.photo({"aero3.jpg"}), bank.photo({"board.jpg"})}, 4800,
			       static_cast<int>(ground.height_m * 120));
		background_.push_back(std::move(ground));
	}

	std::vector<MoverSpec> specs;
	const std::string &scene = config.scene;
	if (scene == "static_near") { // seed experiment 1: a large mover within 2 m, still camera
		specs.push_back({-1.3, 1.7, 0.9, 0, -1.4, 1.4, 0, 0, 0});
	} else if (scene == "static_far") { // experiment 2: several far movers (5-8 m) walking through in turn
		specs.push_back({-4.0, 5.0, 1.3, 0, -4.5, 4.5, 0, 0, 0.0});
		specs.push_back({4.0, 6.0, -1.4, 0, -5.0, 5.0, 0, 0, 1.0});
		specs.push_back({-4.5, 7.0, 1.2, 0, -5.5, 5.5, 0, 0, 2.0});
		specs.push_back({5.0, 8.0, -1.5, 0, -6.0, 6.0, 0, 0, 3.0});
	} else if (scene == "moving_one") { // experiment 3: one mover, the camera pans and sways
		yaw_amplitude_rad_ = 6.0 * std::numbers::pi / 180;
		pitch_amplitude_rad_ = 1.5 * std::numbers::pi / 180;
		sway_amplitude_m_ = 0.10;
		specs.push_back({-1.8, 3.0, 1.1, 0, -2.2, 2.2, 0, 0, 0});
	} else if (scene == "moving_many") { // experiment 4: several movers, moving camera
		yaw_amplitude_rad_ = 6.0 * std::numbers::pi / 180;
		pitch_amplitude_rad_ = 1.5 * std::numbers::pi / 180;
		sway_amplitude_m_ = 0.10;
		specs.push_back({-3.0, 4.5, 1.2, 0, -3.5, 3.5, 0, 0, 0});
		specs.push_back({3.0, 6.0, -1.3, 0, -4.5, 4.5, 0, 0, 0});
		specs.push_back({-1.0, 7.5, 0.9, 0, -5.0, 5.0, 0, 0, 0});
		specs.push_back({1.5, 9.0, 0, -1.0, 0, 0, 5.0, 10.0, 0});
	} else if (scene == "toward") { // a mover walking straight at the camera
		specs.push_back({0.3, 10.0, 0, -1.3, 0, 0, 2.2, 10.5, 0});
	} else if (scene == "walk") {
		// A rig carried forward down a street at walking speed (seed 001's setting): buildings on both sides
		// and street furniture give near static structure; walkers cross, one walks straight at the rig, one
		// keeps pace beside it. 12 m forward and back in 20 s (up to 1.9 m/s), a 1.5 cm bob at 2 steps/s.
		walk_range_m_ = 12;
		walk_period_s_ = 20;
		walk_phase_s_ = 2.5; // already walking at 1.3 m/s on the first frame
		bob_amplitude_m_ = 0.015;
		yaw_amplitude_rad_ = 1.5 * std::numbers::pi / 180;
		sway_amplitude_m_ = 0.03;
		motion_period_s_ = 5;
		specs.push_back({-2.4, 8.0, 1.2, 0, -2.6, 2.6, 0, 0, 0});    // crosses left to right
		specs.push_back({2.2, 14.0, -1.0, 0, -2.6, 2.6, 0, 0, 1.0}); // crosses right to left
		specs.push_back({0.7, 22.0, 0, -1.3, 0, 0, 4.0, 24.0, 0});   // walks at the rig
	} else if (scene == "default") { // a mix: near and far, across, along and toward; slow pan
		yaw_amplitude_rad_ = 4.0 * std::numbers::pi / 180;
		sway_amplitude_m_ = 0.05;
		specs.push_back({-1.8, 2.6, 1.1, 0, -2.2, 2.2, 0, 0, 0});
		specs.push_back({4.0, 7.0, -1.4, 0, -4.5, 4.5, 0, 0, 0});
		specs.push_back({0.9, 9.0, 0, -1.2, 0, 0, 3.5, 9.5, 0});
		specs.push_back({-2.6, 6.0, 0, 0.9, 0, 0, 5.0, 11.0, 0});
	} else if (scene == "rotate") { // no mover: the camera only turns (pans and tilts) on the spot
		yaw_amplitude_rad_ = 6.0 * std::numbers::pi / 180;
		pitch_amplitude_rad_ = 1.5 * std::numbers::pi / 180;
	} else {
		throw SourceError("sim: unknown scene '" + scene +
				  "' (known: default, static_near, static_far, moving_one, moving_many, toward, walk, "
				  "rotate)");
	}

	// Finely textured photographs, used at (nearly) their own resolution: people wear patterned clothes.
	const std::vector<cv::Mat> mover_photos = {bank.photo({"aloeL.jpg"}),	     bank.photo({"baboon.jpg"}),
						   bank.photo({"rubberwhale1.png"}), bank.photo({"starry_night.jpg"}),
						   bank.photo({"stuff.jpg"}),	     bank.photo({"fruits.jpg"})};
	uint8_t id = 1;
	for (const auto &spec : specs) {
		Mover mover;
		mover.id = id++;
		// The seed varies each mover a little, never the scene's character.
		const double jitter = uniform(rng, 0.92, 1.08);
		mover.width_m = spec.width * uniform(rng, 0.9, 1.1);
		mover.height_m = spec.height * uniform(rng, 0.95, 1.05);
		mover.start = {spec.x, kGroundY, spec.z};
		mover.velocity = {spec.vx * jitter, 0, spec.vz * jitter};
		mover.x_bounds = {spec.x_lo, spec.x_hi};
		mover.z_bounds = {spec.z_lo, spec.z_hi};
		mover.start_time_s = spec.start_time;
		mover.texture = mover_texture(mover_photos[(mover.id + config.seed) % mover_photos.size()],
					      mover.width_m, mover.height_m, 400, rng);
		movers_.push_back(std::move(mover));
	}
	if (scene == "walk") {
		// The walker keeping pace: 1.3 m to the right, 3.5 m ahead of the rig, whatever the rig does.
		Mover pacer;
		pacer.id = id++;
		pacer.width_m = 0.6 * uniform(rng, 0.9, 1.1);
		pacer.height_m = 1.75 * uniform(rng, 0.95, 1.05);
		pacer.paces_camera = true;
		pacer.pace_offset = {1.3, kGroundY, 3.5};
		pacer.texture = mover_texture(mover_photos[(pacer.id + config.seed) % mover_photos.size()],
					      pacer.width_m, pacer.height_m, 400, rng);
		movers_.push_back(std::move(pacer));
		// The street: facades on both sides, 3.2 m from the rig's line, and posts and boxes along it.
		const std::array<std::pair<std::vector<std::string>, double>, 2> sides = {
			std::pair{std::vector<std::string>{"building.jpg", "home.jpg", "leuvenA.jpg"}, -3.2},
			std::pair{std::vector<std::string>{"graf1.png", "leuvenB.jpg", "building.jpg"}, 3.2}};
		for (const auto &[photos, x] : sides) {
			TexturedPlane facade;
			facade.width_m = wall_z_ + 6;
			facade.height_m = 6;
			facade.origin = {x, kGroundY - facade.height_m, -6};
			facade.axis_u = {0, 0, 1};
			facade.axis_v = {0, 1, 0};
			std::vector<cv::Mat> tiles;
			for (const auto &name : photos)
				tiles.push_back(bank.photo({name.c_str()}));
			facade.texture = mosaic_grid(tiles, static_cast<int>(facade.width_m * 200), 1200, 400);
			background_.push_back(std::move(facade));
		}
		const std::array<cv::Vec3d, 6> furniture = {cv::Vec3d{-2.2, 0, 5.5},  cv::Vec3d{2.3, 0, 10.0},
							    cv::Vec3d{-2.0, 0, 16.0}, cv::Vec3d{2.1, 0, 21.0},
							    cv::Vec3d{-2.3, 0, 26.0}, cv::Vec3d{1.9, 0, 30.0}};
		const std::vector<cv::Mat> box_photos = {bank.photo({"box.png"}), bank.photo({"fruits.jpg"}),
							 bank.photo({"blox.jpg"}), bank.photo({"board.jpg"})};
		for (size_t k = 0; k < furniture.size(); ++k) {
			TexturedPlane box;
			box.width_m = 0.8;
			box.height_m = 1.2;
			box.origin = {furniture[k][0] - box.width_m / 2, kGroundY - box.height_m, furniture[k][2]};
			box.axis_u = {1, 0, 0};
			box.axis_v = {0, 1, 0};
			box.texture =
				mover_texture(box_photos[k % box_photos.size()], box.width_m, box.height_m, 300, rng);
			furniture_.push_back(std::move(box));
		}
	}
	if (movers_.size() > FrameTruth::kMaxObjects)
		throw SourceError("sim: too many movers");
}

std::pair<cv::Vec3d, cv::Vec3d> Scene::camera_centre(double t) const
{
	const double phase = 2 * std::numbers::pi * t / motion_period_s_;
	cv::Vec3d centre(sway_amplitude_m_ * std::sin(0.6 * phase + 1.0), 0, 0);
	cv::Vec3d velocity(
		sway_amplitude_m_ * std::cos(0.6 * phase + 1.0) * 0.6 * 2 * std::numbers::pi / motion_period_s_, 0, 0);
	if (walk_range_m_ > 0) {
		const double w = 2 * std::numbers::pi / walk_period_s_;
		centre[2] = walk_range_m_ * (1 - std::cos(w * (t + walk_phase_s_))) / 2;
		velocity[2] = walk_range_m_ * w * std::sin(w * (t + walk_phase_s_)) / 2;
		const double s = 2 * std::numbers::pi * step_frequency_hz_;
		centre[1] = -bob_amplitude_m_ * std::abs(std::sin(s * t / 2));
		velocity[1] = -bob_amplitude_m_ * std::cos(s * t / 2) * s / 2 * (std::sin(s * t / 2) >= 0 ? 1 : -1);
	}
	return {centre, velocity};
}

std::pair<cv::Vec3d, cv::Vec3d> Scene::mover_state(const Mover &mover, double t) const
{
	if (!mover.paces_camera)
		return mover.state_at(t);
	const auto [centre, velocity] = camera_centre(t);
	return {cv::Vec3d(centre[0] + mover.pace_offset[0], mover.pace_offset[1], centre[2] + mover.pace_offset[2]),
		cv::Vec3d(velocity[0], 0, velocity[2])};
}

Pose Scene::left_pose(double t) const
{
	const double phase = 2 * std::numbers::pi * t / motion_period_s_;
	const cv::Matx33d r_wc = rotation_y(yaw_amplitude_rad_ * std::sin(phase)) *
				 rotation_x(pitch_amplitude_rad_ * std::sin(1.7 * phase + 0.5));
	const cv::Vec3d centre = camera_centre(t).first;
	const cv::Matx33d r_cw = r_wc.t();
	return {r_cw, -(r_cw * centre)};
}

Pose Scene::right_pose(double t) const
{
	Pose pose = left_pose(t);
	// The right camera sits baseline_m along the left camera's x axis: x_right = x_left - b.
	pose.t_cw -= cv::Vec3d(config_.baseline_m, 0, 0);
	return pose;
}

void Scene::draw_plane(const TexturedPlane &plane, const Pose &pose, cv::Mat &image, cv::Mat &object_ids,
		       cv::Mat &depth, RenderScratch &scratch) const
{
	const std::array<cv::Vec3d, 4> world = {plane.origin, plane.origin + plane.width_m * plane.axis_u,
						plane.origin + plane.width_m * plane.axis_u +
							plane.height_m * plane.axis_v,
						plane.origin + plane.height_m * plane.axis_v};
	std::array<cv::Vec3d, 4> cam;
	for (size_t i = 0; i < 4; ++i)
		cam[i] = pose.r_cw * world[i] + pose.t_cw;
	std::array<cv::Vec3d, 8> clipped;
	const size_t n = clip_near(cam, clipped);
	if (n < 3)
		return;

	const CameraIntrinsics &k = intrinsics_;
	std::array<cv::Point, 8> polygon; // 4 fractional bits
	double min_x = 1e18, min_y = 1e18, max_x = -1e18, max_y = -1e18;
	for (size_t i = 0; i < n; ++i) {
		const double u = k.fx * clipped[i][0] / clipped[i][2] + k.cx;
		const double v = k.fy * clipped[i][1] / clipped[i][2] + k.cy;
		min_x = std::min(min_x, u), max_x = std::max(max_x, u);
		min_y = std::min(min_y, v), max_y = std::max(max_y, v);
		polygon[i] = {static_cast<int>(std::lround(std::clamp(u, -1e5, 1e5) * 16)),
			      static_cast<int>(std::lround(std::clamp(v, -1e5, 1e5) * 16))};
	}
	const cv::Rect roi = cv::Rect(cv::Point(static_cast<int>(std::floor(std::max(min_x, 0.0))),
						static_cast<int>(std::floor(std::max(min_y, 0.0)))),
				      cv::Point(static_cast<int>(std::ceil(std::min(max_x + 1, double(image.cols)))),
						static_cast<int>(std::ceil(std::min(max_y + 1, double(image.rows)))))) &
			     cv::Rect(0, 0, image.cols, image.rows);
	if (roi.empty())
		return;
	for (size_t i = 0; i < n; ++i)
		polygon[i] -= cv::Point(roi.x * 16, roi.y * 16);

	// Texture pixel (s, t) -> world origin + s/ppm_u axis_u + t/ppm_v axis_v -> camera -> image.
	const double ppm_u = plane.texture.cols / plane.width_m;
	const double ppm_v = plane.texture.rows / plane.height_m;
	const cv::Vec3d c0 = pose.r_cw * (plane.axis_u * (1.0 / ppm_u));
	const cv::Vec3d c1 = pose.r_cw * (plane.axis_v * (1.0 / ppm_v));
	const cv::Vec3d c2 = pose.r_cw * plane.origin + pose.t_cw;
	const cv::Matx33d columns(c0[0], c1[0], c2[0], c0[1], c1[1], c2[1], c0[2], c1[2], c2[2]);
	const cv::Matx33d shift(1, 0, -roi.x, 0, 1, -roi.y, 0, 0, 1);
	const cv::Matx33d h = shift * k.matrix() * columns;

	// Sub-views of the full-frame scratch buffers: warpPerspective writes into them without allocating.
	cv::Mat tile_bgr = scratch.tile(cv::Rect(0, 0, roi.width, roi.height));
	cv::Mat mask_u8 = scratch.mask(cv::Rect(0, 0, roi.width, roi.height));
	cv::warpPerspective(plane.texture, tile_bgr, h, roi.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT_101);
	mask_u8.setTo(0);
	cv::fillConvexPoly(mask_u8, polygon.data(), static_cast<int>(n), cv::Scalar(255), cv::LINE_8, 4);
	tile_bgr.copyTo(image(roi), mask_u8);
	if (!object_ids.empty())
		object_ids(roi).setTo(plane.object_id, mask_u8);
	if (!depth.empty()) {
		// Inverse depth is affine in (u, v) on a plane: 1/z = n.(K^-1 p) / d.
		const cv::Vec3d normal = pose.r_cw * plane.axis_u.cross(plane.axis_v);
		const double d = normal.dot(c2);
		const double a = normal[0] / k.fx / d, b = normal[1] / k.fy / d;
		const double c = (normal[2] - normal[0] * k.cx / k.fx - normal[1] * k.cy / k.fy) / d;
		for (int y = 0; y < roi.height; ++y) {
			const uint8_t *m = mask_u8.ptr<uint8_t>(y);
			float *z = depth.ptr<float>(roi.y + y) + roi.x;
			const double v = roi.y + y;
			for (int x = 0; x < roi.width; ++x)
				if (m[x])
					z[x] = static_cast<float>(1.0 / (a * (roi.x + x) + b * v + c));
		}
	}
}

void Scene::render(double t, const Pose &pose, cv::Mat &image, cv::Mat &object_ids, cv::Mat &depth,
		   RenderScratch &scratch) const
{
	scratch.tile.create(image.size(), CV_8UC3); // allocates on the first call only
	scratch.mask.create(image.size(), CV_8UC1);
	image.setTo(cv::Scalar(40, 40, 40));
	if (!object_ids.empty())
		object_ids.setTo(0);
	if (!depth.empty())
		depth.setTo(0);
	for (const auto &plane : background_)
		draw_plane(plane, pose, image, object_ids, depth, scratch);
	// Street furniture far to near (static, so it never hides behind the wall or ground).
	std::array<std::pair<double, size_t>, 16> furniture_order{};
	const size_t furniture_count = std::min(furniture_.size(), furniture_order.size());
	for (size_t i = 0; i < furniture_count; ++i)
		furniture_order[i] = {(pose.r_cw * furniture_[i].origin + pose.t_cw)[2], i};
	std::sort(furniture_order.begin(), furniture_order.begin() + static_cast<std::ptrdiff_t>(furniture_count),
		  [](const auto &a, const auto &b) { return a.first > b.first; });
	for (size_t k = 0; k < furniture_count; ++k)
		draw_plane(furniture_[furniture_order[k].second], pose, image, object_ids, depth, scratch);

	// Movers far to near, so nearer ones cover farther ones (they never intersect: all stand upright).
	std::array<std::pair<double, size_t>, FrameTruth::kMaxObjects> order{};
	size_t count = 0;
	for (size_t i = 0; i < movers_.size(); ++i) {
		if (t < movers_[i].start_time_s)
			continue;
		const cv::Vec3d cam = pose.r_cw * mover_state(movers_[i], t).first + pose.t_cw;
		order[count++] = {cam[2], i};
	}
	std::sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(count),
		  [](const auto &a, const auto &b) { return a.first > b.first; });
	for (size_t k = 0; k < count; ++k) {
		const Mover &mover = movers_[order[k].second];
		const cv::Vec3d bottom = mover_state(mover, t).first;
		TexturedPlane board;
		board.origin = bottom + cv::Vec3d(-mover.width_m / 2, -mover.height_m, 0);
		board.axis_u = {1, 0, 0};
		board.axis_v = {0, 1, 0};
		board.width_m = mover.width_m;
		board.height_m = mover.height_m;
		board.texture = mover.texture; // shares the pixels
		board.object_id = mover.id;
		draw_plane(board, pose, image, object_ids, depth, scratch);
	}
}

void Scene::fill_truth(double t, FrameTruth &truth) const
{
	const Pose pose = left_pose(t);
	const cv::Matx33d r_wc = pose.r_cw.t();
	const cv::Vec3d centre = -(r_wc * pose.t_cw);
	for (int r = 0; r < 3; ++r) {
		for (int c = 0; c < 3; ++c)
			truth.camera_pose[static_cast<size_t>(r * 4 + c)] = r_wc(r, c);
		truth.camera_pose[static_cast<size_t>(r * 4 + 3)] = centre[r];
	}
	truth.object_count = 0;
	for (const auto &mover : movers_) {
		if (t < mover.start_time_s)
			continue;
		const auto [bottom, velocity] = mover_state(mover, t);
		const cv::Vec3d centre_w = bottom + cv::Vec3d(0, -mover.height_m / 2, 0);
		const cv::Vec3d p = pose.r_cw * centre_w + pose.t_cw;
		const cv::Vec3d v = pose.r_cw * velocity;
		truth.objects[truth.object_count++] = {mover.id, {p[0], p[1], p[2]}, {v[0], v[1], v[2]}};
	}
}

} // namespace stereod::drivers::sim
