#include "tools/group_eval.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <numbers>
#include <sstream>

#include <nlohmann/json.hpp>

namespace stereod::tools {

namespace {

/// Per mask id: its pixel count and their bounding box (empty where the id does not occur).
struct Blobs {
	std::array<int, 256> pixels{};
	std::array<cv::Rect, 256> boxes{};
};

Blobs blobs_of(const cv::Mat &mask)
{
	Blobs b;
	for (int y = 0; y < mask.rows; ++y) {
		const auto *row = mask.ptr<uint8_t>(y);
		for (int x = 0; x < mask.cols; ++x) {
			if (row[x] == 0)
				continue;
			b.boxes[row[x]] =
				b.pixels[row[x]]++ == 0 ? cv::Rect(x, y, 1, 1) : b.boxes[row[x]] | cv::Rect(x, y, 1, 1);
		}
	}
	return b;
}

} // namespace

std::vector<TrueMover> visible_movers(const cv::Mat &mask, const nlohmann::json &truth, int min_pixels)
{
	std::vector<TrueMover> movers;
	if (mask.empty())
		return movers;
	const auto [pixels, boxes] = blobs_of(mask);
	cv::Matx33d r_wc = cv::Matx33d::eye();
	if (truth.contains("camera_pose"))
		for (int r = 0; r < 3; ++r)
			for (int c = 0; c < 3; ++c)
				r_wc(r, c) = truth["camera_pose"][static_cast<size_t>(r * 4 + c)].get<double>();
	if (!truth.contains("objects")) {
		for (int id = 1; id < 256; ++id)
			if (pixels[static_cast<size_t>(id)] >= min_pixels) {
				TrueMover m;
				m.id = id;
				m.pixels = pixels[static_cast<size_t>(id)];
				m.box = boxes[static_cast<size_t>(id)];
				m.metric = false;
				movers.push_back(m);
			}
		return movers;
	}
	for (const auto &object : truth.value("objects", nlohmann::json::array())) {
		const int id = object.at("id").get<int>();
		if (id <= 0 || id > 255 || pixels[static_cast<size_t>(id)] < min_pixels)
			continue;
		TrueMover m;
		m.id = id;
		m.pixels = pixels[static_cast<size_t>(id)];
		m.box = boxes[static_cast<size_t>(id)];
		const auto p = object.at("position_m").get<std::array<double, 3>>();
		const auto v = object.at("velocity_mps").get<std::array<double, 3>>();
		m.position_m = {p[0], p[1], p[2]};
		m.world_velocity_mps = r_wc * cv::Vec3d(v[0], v[1], v[2]);
		m.walking = cv::norm(m.world_velocity_mps) > 0;
		movers.push_back(m);
	}
	return movers;
}

namespace {

/// A group's box as the mask's pixels it covers (rounded outwards), clipped to the mask.
cv::Rect pixel_box(const TargetGroup &g, const cv::Mat &mask)
{
	return cv::Rect(cv::Point(static_cast<int>(std::floor(g.box_px[0])), static_cast<int>(std::floor(g.box_px[1]))),
			cv::Point(static_cast<int>(std::ceil(g.box_px[2])) + 1,
				  static_cast<int>(std::ceil(g.box_px[3])) + 1)) &
	       cv::Rect(0, 0, mask.cols, mask.rows);
}

/// How far the blob that overlaps mover `id` of `mask` most in `other` lies from it: box centres across,
/// bottoms down; nullopt when no blob of `other` overlaps it.
std::optional<double> partner_shift(const cv::Mat &mask, int id, const cv::Rect &box, const cv::Mat &other,
				    const std::array<cv::Rect, 256> &other_boxes)
{
	if (other.empty() || other.size() != mask.size())
		return std::nullopt;
	std::array<int, 256> overlap{};
	for (int y = box.y; y < box.y + box.height; ++y) {
		const auto *row = mask.ptr<uint8_t>(y);
		const auto *there = other.ptr<uint8_t>(y);
		for (int x = box.x; x < box.x + box.width; ++x)
			if (row[x] == id && there[x] != 0)
				++overlap[there[x]];
	}
	const auto best = std::max_element(overlap.begin() + 1, overlap.end());
	if (*best == 0)
		return std::nullopt;
	const cv::Rect &b = other_boxes[static_cast<size_t>(best - overlap.begin())];
	return std::hypot((b.x + 0.5 * b.width) - (box.x + 0.5 * box.width),
			  static_cast<double>((b.y + b.height) - (box.y + box.height)));
}

} // namespace

void mark_walking(std::vector<TrueMover> &movers, const cv::Mat &mask, const cv::Mat &before, const cv::Mat &after,
		  double min_move_px)
{
	const auto before_boxes = blobs_of(before).boxes, after_boxes = blobs_of(after).boxes;
	for (auto &mover : movers) {
		if (mover.metric)
			continue;
		const auto earlier = partner_shift(mask, mover.id, mover.box, before, before_boxes);
		const auto later = partner_shift(mask, mover.id, mover.box, after, after_boxes);
		mover.walking = (!earlier && !later) || (earlier && *earlier >= min_move_px) ||
				(later && *later >= min_move_px);
	}
}

std::vector<int> match_groups(const std::vector<TargetGroup> &groups, const cv::Mat &mask, double min_share)
{
	std::vector<int> matched;
	for (const auto &g : groups) {
		const cv::Rect box = pixel_box(g, mask);
		std::map<int, int> count;
		for (int y = box.y; y < box.y + box.height; ++y) {
			const auto *row = mask.ptr<uint8_t>(y);
			for (int x = box.x; x < box.x + box.width; ++x)
				if (row[x] != 0)
					++count[row[x]];
		}
		int best = 0, best_count = 0;
		for (const auto &[id, n] : count)
			if (n > best_count) {
				best = id;
				best_count = n;
			}
		const double area = std::max(1.0, static_cast<double>(box.area()));
		matched.push_back(static_cast<double>(best_count) / area >= min_share ? best : 0);
	}
	return matched;
}

bool movers_separated(const std::vector<TrueMover> &movers, int margin_px)
{
	for (size_t i = 0; i < movers.size(); ++i)
		for (size_t j = i + 1; j < movers.size(); ++j) {
			const cv::Rect grown(movers[i].box.x - margin_px, movers[i].box.y - margin_px,
					     movers[i].box.width + 2 * margin_px, movers[i].box.height + 2 * margin_px);
			if ((grown & movers[j].box).area() > 0)
				return false;
		}
	return true;
}

namespace {

/// GroupScore::walking_labels for one frame: `mask` holds the movers' ids.
void score_walking_labels(const FrameResult &result, const cv::Mat &mask, const std::vector<TrueMover> &movers,
			  LabelScore &score)
{
	// Per mask id: 1 a walking mover, 0 not counted, and the scene (id 0) its own case.
	std::array<uint8_t, 256> walking{};
	for (const TrueMover &mover : movers)
		if (mover.id > 0 && mover.id < 256)
			walking[static_cast<size_t>(mover.id)] = mover.walking ? 1 : 0;
	++score.frames;
	for (const LabelledPoint &point : result.points) {
		const int x = cvRound(point.u), y = cvRound(point.v);
		if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows)
			continue;
		const uint8_t id = mask.at<uint8_t>(y, x);
		if (id != 0 && walking[id] == 0)
			continue;
		score.add(point.label, id != 0);
	}
}

} // namespace

void GroupScore::add(const FrameResult &result, const cv::Mat &mask, const std::vector<TrueMover> &movers)
{
	++frames;
	const auto &gs = result.groups;
	groups += gs.size();
	if (movers.empty()) {
		++frames_without_movers;
		groups_without_movers += gs.size();
	}
	const bool separated = !movers.empty() && movers_separated(movers, separation_margin_px);
	const std::vector<int> on = match_groups(gs, mask);
	if (separated) {
		++frames_separated;
		// The frame's feature points on each mover (mask ids, any label).
		std::array<int, 256> points_on{};
		for (const LabelledPoint &point : result.points) {
			const int x = cvRound(point.u), y = cvRound(point.v);
			if (x >= 0 && y >= 0 && x < mask.cols && y < mask.rows)
				++points_on[mask.at<uint8_t>(y, x)];
		}
		const auto seen = [&](const TrueMover &mover) {
			return mover.id > 0 && mover.id < 256 &&
			       points_on[static_cast<size_t>(mover.id)] >= seen_min_points;
		};
		if (std::all_of(movers.begin(), movers.end(), seen)) {
			++frames_seen;
			count_exact_seen += gs.size() == movers.size() ? 1 : 0;
		}
		count_exact += gs.size() == movers.size() ? 1 : 0;
		count_over += gs.size() > movers.size() ? 1 : 0;
		count_under += gs.size() < movers.size() ? 1 : 0;
		separated_groups += gs.size();
		separated_groups_off += static_cast<uint64_t>(std::count(on.begin(), on.end(), 0));
		for (const auto &mover : movers) {
			const auto groups_on = std::count(on.begin(), on.end(), mover.id);
			++separated_mover_views;
			separated_movers_split += groups_on >= 2 ? 1 : 0;
			separated_movers_missed += groups_on == 0 ? 1 : 0;
			if (!mover.metric)
				continue; // a pixels-only reference's ids are per frame
			MoverCount &count = by_mover[mover.id];
			++count.views;
			count.split += groups_on >= 2 ? 1 : 0;
			const bool unseen = !seen(mover);
			count.unseen += unseen ? 1 : 0;
			if (groups_on == 0) {
				++count.missed;
				count.missed_unseen += unseen ? 1 : 0;
				count.missed_frames.push_back(result.seq);
			}
		}
	}
	score_walking_labels(result, mask, movers, walking_labels);
	std::vector<cv::Rect> boxes;
	boxes.reserve(gs.size());
	for (const auto &g : gs)
		boxes.push_back(pixel_box(g, mask));
	for (const auto &mover : movers) {
		++mover_views;
		// The mover's pixels inside the union of the boxes of groups on movers, and whether any box touches it.
		int inside = 0;
		bool touched = false;
		for (int y = mover.box.y; y < mover.box.y + mover.box.height; ++y) {
			const auto *row = mask.ptr<uint8_t>(y);
			for (int x = mover.box.x; x < mover.box.x + mover.box.width; ++x) {
				if (row[x] != mover.id)
					continue;
				bool in_any = false, in_on = false;
				for (size_t i = 0; i < boxes.size() && !in_on; ++i)
					if (boxes[i].contains({x, y})) {
						in_any = true;
						in_on = on[i] != 0;
					}
				touched = touched || in_any;
				inside += in_on ? 1 : 0;
			}
		}
		movers_inside += inside >= inside_share * std::max(1, mover.pixels) ? 1 : 0;
		// The group covering this mover; of several, the one with the most points.
		const TargetGroup *best = nullptr;
		for (size_t i = 0; i < gs.size(); ++i)
			if (on[i] == mover.id && (best == nullptr || gs[i].point_count > best->point_count))
				best = &gs[i];
		walking_views += mover.walking ? 1 : 0;
		if (best == nullptr) {
			movers_untouched += touched ? 0 : 1;
			continue;
		}
		++movers_covered;
		walking_covered += mover.walking ? 1 : 0;
		if (!mover.metric)
			continue;
		if (const auto it = last_group_of_mover.find(mover.id);
		    it != last_group_of_mover.end() && it->second != best->id) {
			++id_switches;
			by_mover[mover.id].id_switch_frames.push_back(result.seq);
		}
		last_group_of_mover[mover.id] = best->id;
		if (best->position_m) {
			const auto &p = *best->position_m;
			centroid_error_m.push_back(cv::norm(cv::Vec3d(p[0], p[1], p[2]) - mover.position_m));
		}
		const double true_speed = cv::norm(mover.world_velocity_mps);
		if (best->speed_mps && true_speed > 1e-6) {
			const double error = std::abs(*best->speed_mps - true_speed) / true_speed;
			speed_relative_error.push_back(error);
			by_mover[mover.id].speed_relative_error.push_back(error);
			if (best->speed_sigma_mps && *best->speed_sigma_mps > 0)
				speed_error_sigmas.push_back(std::abs(*best->speed_mps - true_speed) /
							     *best->speed_sigma_mps);
		}
		const cv::Vec3d &v = mover.world_velocity_mps;
		const double ground_speed = std::hypot(v[0], v[2]);
		if (best->heading_rad && ground_speed >= min_heading_speed_mps &&
		    cv::norm(mover.position_m) <= max_heading_distance_m) {
			double d = *best->heading_rad - std::atan2(v[0], v[2]);
			d = std::remainder(d, 2 * std::numbers::pi);
			heading_error_deg.push_back(std::abs(d) * 180 / std::numbers::pi);
		}
	}
	for (size_t i = 0; i < gs.size(); ++i)
		groups_on_movers += on[i] != 0 ? 1 : 0;
}

double fraction_below(const std::vector<double> &values, double limit)
{
	if (values.empty())
		return std::nan("");
	return static_cast<double>(std::count_if(values.begin(), values.end(), [&](double v) { return v < limit; })) /
	       static_cast<double>(values.size());
}

std::string group_score_table(const std::string &name, const GroupScore &s)
{
	std::ostringstream out;
	const auto ratio = [](uint64_t a, uint64_t b) {
		return b > 0 ? static_cast<double>(a) / static_cast<double>(b) : std::nan("");
	};
	out << std::fixed << std::setprecision(3);
	out << "| scene | frames | separated frames | count exact | groups | on a mover | groups with no mover in view "
	       "| "
	       "mover views covered | inside a group box | untouched | centroid error m (median) | speed error "
	       "(median) | speed within 10% | heading error deg (median) | heading within 15 deg | id switches | "
	       "walking views | walking covered | walking labels precision | recall | F1 | speed within 1 sigma | "
	       "within 2 sigma |\n";
	out << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
	out << "| " << name << " | " << s.frames << " | " << s.frames_separated << " | "
	    << ratio(s.count_exact, s.frames_separated) << " | " << s.groups << " | "
	    << ratio(s.groups_on_movers, s.groups) << " | " << s.groups_without_movers << " | "
	    << ratio(s.movers_covered, s.mover_views) << " | " << ratio(s.movers_inside, s.mover_views) << " | "
	    << ratio(s.movers_untouched, s.mover_views) << " | " << median(s.centroid_error_m) << " | "
	    << median(s.speed_relative_error) << " | " << fraction_below(s.speed_relative_error, 0.10) << " | "
	    << std::setprecision(1) << median(s.heading_error_deg) << " | " << std::setprecision(3)
	    << fraction_below(s.heading_error_deg, 15.0) << " | " << s.id_switches << " | " << s.walking_views << " | "
	    << ratio(s.walking_covered, s.walking_views) << " | " << s.walking_labels.precision() << " | "
	    << s.walking_labels.recall() << " | " << s.walking_labels.f1() << " | "
	    << fraction_below(s.speed_error_sigmas, 1.0) << " | " << fraction_below(s.speed_error_sigmas, 2.0)
	    << " |\n";
	return out.str();
}

std::string group_count_table(const std::string &name, const GroupScore &s)
{
	std::ostringstream out;
	const auto ratio = [](uint64_t a, uint64_t b) {
		return b > 0 ? static_cast<double>(a) / static_cast<double>(b) : std::nan("");
	};
	out << std::fixed << std::setprecision(3);
	out << "| scene | separated frames | count exact | too many groups | too few | mover views | split (>= 2 "
	       "groups) | missed (none) | groups | on no mover | frames every mover on >= "
	    << s.seen_min_points << " points | count exact there |\n";
	out << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
	out << "| " << name << " | " << s.frames_separated << " | " << ratio(s.count_exact, s.frames_separated) << " | "
	    << ratio(s.count_over, s.frames_separated) << " | " << ratio(s.count_under, s.frames_separated) << " | "
	    << s.separated_mover_views << " | " << ratio(s.separated_movers_split, s.separated_mover_views) << " | "
	    << ratio(s.separated_movers_missed, s.separated_mover_views) << " | " << s.separated_groups << " | "
	    << ratio(s.separated_groups_off, s.separated_groups) << " | " << s.frames_seen << " | "
	    << ratio(s.count_exact_seen, s.frames_seen) << " |\n";
	return out.str();
}

namespace {

/// Frame numbers (in order) with runs of consecutive ones as ranges: a mover missed while it enters is one
/// run, not ten numbers.
std::string as_runs(const std::vector<uint64_t> &f)
{
	std::ostringstream out;
	for (size_t i = 0; i < f.size();) {
		size_t j = i;
		while (j + 1 < f.size() && f[j + 1] == f[j] + 1)
			++j;
		out << (i > 0 ? ", " : "") << f[i];
		if (j > i)
			out << "-" << f[j];
		i = j + 1;
	}
	return out.str();
}

} // namespace

std::string group_mover_table(const GroupScore &s)
{
	std::ostringstream out;
	out << std::setprecision(3);
	out << "| mover (mask id) | separated views | on < " << s.seen_min_points << " points | missed | of those on < "
	    << s.seen_min_points
	    << " | split | speed error (median, all views) | frames missed | id switches (frames) |\n";
	out << "|---|---|---|---|---|---|---|---|---|\n";
	for (const auto &[id, count] : s.by_mover) {
		out << "| " << id << " | " << count.views << " | " << count.unseen << " | " << count.missed << " | "
		    << count.missed_unseen << " | " << count.split << " | " << median(count.speed_relative_error)
		    << " | ";
		out << as_runs(count.missed_frames) << " | " << count.id_switch_frames.size();
		if (!count.id_switch_frames.empty())
			out << " (" << as_runs(count.id_switch_frames) << ")";
		out << " |\n";
	}
	return out.str();
}

} // namespace stereod::tools
