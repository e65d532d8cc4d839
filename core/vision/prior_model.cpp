#include "core/vision/prior_model.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <map>

#include <opencv2/imgproc.hpp>

namespace stereod::vision {

namespace {

const std::pair<std::string_view, PriorCategory> kCategoryNames[] = {
	{"dynamic", PriorCategory::Dynamic},
	{"potentially_dynamic", PriorCategory::PotentiallyDynamic},
};

std::string_view trim(std::string_view s)
{
	while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
		s.remove_prefix(1);
	while (!s.empty() && (s.back() == ' ' || s.back() == '\t'))
		s.remove_suffix(1);
	return s;
}

const ModelClass *mapped(std::span<const ModelClass> classes, int id)
{
	for (const ModelClass &c : classes)
		if (c.id == id)
			return &c;
	return nullptr;
}

std::string shape_of(const cv::Mat &m)
{
	std::string s;
	for (int i = 0; i < m.dims; ++i)
		s += (i > 0 ? " x " : "") + std::to_string(m.size[i]);
	return s;
}

/// A box in input pixels (centre, size) -> image pixels, clipped.
cv::Rect2f image_box(float cx, float cy, float w, float h, const Letterbox &box, cv::Size image)
{
	const auto s = static_cast<float>(1.0 / box.scale);
	const cv::Rect2f r((cx - w / 2) * s, (cy - h / 2) * s, w * s, h * s);
	return r & cv::Rect2f(0, 0, static_cast<float>(image.width), static_cast<float>(image.height));
}

} // namespace

std::vector<ModelClass> parse_class_map(std::string_view text)
{
	std::vector<ModelClass> classes;
	while (!text.empty()) {
		const size_t comma = text.find(',');
		const std::string_view item = trim(text.substr(0, comma));
		text = comma == std::string_view::npos ? std::string_view() : text.substr(comma + 1);
		const size_t colon = item.find(':');
		const std::string quoted = "'" + std::string(item) + "'";
		if (colon == std::string_view::npos)
			throw std::invalid_argument(quoted + ": want class:category, e.g. 0:dynamic");
		const std::string_view id_text = trim(item.substr(0, colon));
		const std::string_view category_text = trim(item.substr(colon + 1));
		ModelClass c;
		const auto [end, error] = std::from_chars(id_text.data(), id_text.data() + id_text.size(), c.id);
		if (error != std::errc() || end != id_text.data() + id_text.size() || c.id < 0)
			throw std::invalid_argument(quoted +
						    ": the class must be the model's class number (0, 1, ...)");
		bool known = false;
		for (const auto &[name, category] : kCategoryNames)
			if (name == category_text) {
				c.category = category;
				known = true;
			}
		if (!known)
			throw std::invalid_argument(quoted + ": the category must be dynamic or potentially_dynamic");
		if (mapped(classes, c.id) != nullptr)
			throw std::invalid_argument(quoted + ": class " + std::to_string(c.id) + " is mapped twice");
		classes.push_back(c);
	}
	if (classes.empty())
		throw std::invalid_argument("map at least one class, e.g. 0:dynamic");
	return classes;
}

std::string format_class_map(std::span<const ModelClass> classes)
{
	std::string out;
	for (const ModelClass &c : classes) {
		out += out.empty() ? "" : ",";
		out += std::to_string(c.id) + ":";
		for (const auto &[name, category] : kCategoryNames)
			if (category == c.category)
				out += name;
	}
	return out;
}

Letterbox letterbox_for(cv::Size image, cv::Size input)
{
	Letterbox box;
	if (image.width <= 0 || image.height <= 0)
		return box;
	box.scale = std::min(static_cast<double>(input.width) / image.width,
			     static_cast<double>(input.height) / image.height);
	box.content = cv::Size(std::max(1, static_cast<int>(std::lround(image.width * box.scale))),
			       std::max(1, static_cast<int>(std::lround(image.height * box.scale))));
	box.content.width = std::min(box.content.width, input.width);
	box.content.height = std::min(box.content.height, input.height);
	return box;
}

std::vector<PriorRegion> decode_detections(const cv::Mat &output, const PriorModelSpec &spec, const Letterbox &box,
					   cv::Size image, double margin)
{
	const bool v8 = spec.layout == ModelLayout::Yolov8;
	const int head = v8 ? 4 : 5; // values before the class scores
	// Accept 1 x A x B and A x B.
	if (output.type() != CV_32F || output.dims < 2 || output.dims > 3 || (output.dims == 3 && output.size[0] != 1))
		throw std::runtime_error("detector output " + shape_of(output) + ": want 1 x rows x columns, float");
	const int a = output.size[output.dims - 2];
	const int b = output.size[output.dims - 1];
	const int values = v8 ? a : b;	   // per candidate
	const int candidates = v8 ? b : a; // how many
	const int classes = values - head;
	if (classes < 1)
		throw std::runtime_error("detector output " + shape_of(output) + ": " + (v8 ? "yolov8" : "yolov5") +
					 " wants " + std::to_string(head) + " + classes values per candidate " +
					 (v8 ? "(1 x (4 + C) x N)" : "(1 x N x (5 + C))"));
	const auto *data = output.ptr<float>();
	const auto at = [&](int candidate, int value) {
		return v8 ? data[static_cast<size_t>(value) * static_cast<size_t>(b) + static_cast<size_t>(candidate)]
			  : data[static_cast<size_t>(candidate) * static_cast<size_t>(b) + static_cast<size_t>(value)];
	};
	// Candidates per mapped class, then non-maximum suppression per class.
	std::map<int, std::pair<std::vector<cv::Rect2d>, std::vector<float>>> by_class;
	for (int i = 0; i < candidates; ++i) {
		int best = 0;
		float best_score = at(i, head);
		for (int c = 1; c < classes; ++c)
			if (at(i, head + c) > best_score) {
				best = c;
				best_score = at(i, head + c);
			}
		const float score = v8 ? best_score : best_score * at(i, 4);
		if (score < spec.min_confidence || !std::isfinite(score) || mapped(spec.classes, best) == nullptr)
			continue;
		const cv::Rect2f r = image_box(at(i, 0), at(i, 1), at(i, 2), at(i, 3), box, image);
		if (r.area() <= 0)
			continue;
		by_class[best].first.emplace_back(r.x, r.y, r.width, r.height);
		by_class[best].second.push_back(score);
	}
	std::vector<PriorRegion> regions;
	const cv::Rect2f frame(0, 0, static_cast<float>(image.width), static_cast<float>(image.height));
	for (const auto &[id, found] : by_class) {
		std::vector<int> kept;
		cv::dnn::NMSBoxes(found.first, found.second, static_cast<float>(spec.min_confidence),
				  static_cast<float>(spec.nms_iou), kept);
		for (const int k : kept) {
			const cv::Rect2d &r = found.first[static_cast<size_t>(k)];
			const auto mx = static_cast<float>(margin * r.width);
			const auto my = static_cast<float>(margin * r.height);
			const cv::Rect2f grown(static_cast<float>(r.x) - mx, static_cast<float>(r.y) - my,
					       static_cast<float>(r.width) + 2 * mx,
					       static_cast<float>(r.height) + 2 * my);
			PriorRegion region;
			region.box = grown & frame;
			region.score = found.second[static_cast<size_t>(k)];
			region.category = mapped(spec.classes, id)->category;
			region.class_id = id;
			regions.push_back(std::move(region));
		}
	}
	std::sort(regions.begin(), regions.end(),
		  [](const PriorRegion &x, const PriorRegion &y) { return x.score > y.score; });
	return regions;
}

std::vector<PriorRegion> decode_segmentation(const cv::Mat &output, const PriorModelSpec &spec, const Letterbox &box,
					     cv::Size image)
{
	if (output.type() != CV_32F || !((output.dims == 4 && output.size[0] == 1) || output.dims == 3))
		throw std::runtime_error("segmentation output " + shape_of(output) +
					 ": want 1 x C x h x w class scores or 1 x h x w class ids, float");
	const int channels = output.dims == 4 ? output.size[1] : 1;
	const int h = output.size[output.dims - 2];
	const int w = output.size[output.dims - 1];
	const auto plane = static_cast<size_t>(h) * static_cast<size_t>(w);
	const auto *data = output.ptr<float>();
	// Per output pixel: the class (argmax of the scores, or the value itself when there is one channel).
	cv::Mat classes(h, w, CV_32S);
	for (int y = 0; y < h; ++y)
		for (int x = 0; x < w; ++x) {
			const size_t at = static_cast<size_t>(y) * static_cast<size_t>(w) + static_cast<size_t>(x);
			int best = 0;
			if (channels == 1) {
				best = static_cast<int>(std::lround(data[at]));
			} else {
				for (int c = 1; c < channels; ++c)
					if (data[static_cast<size_t>(c) * plane + at] >
					    data[static_cast<size_t>(best) * plane + at])
						best = c;
			}
			classes.at<int>(y, x) = best;
		}
	// The output covers the network's input; the image is its top-left `content` part.
	const double to_output_x = static_cast<double>(w) / spec.input_width;
	const double to_output_y = static_cast<double>(h) / spec.input_height;
	const cv::Rect content(0, 0, std::clamp(static_cast<int>(std::lround(box.content.width * to_output_x)), 1, w),
			       std::clamp(static_cast<int>(std::lround(box.content.height * to_output_y)), 1, h));
	std::vector<PriorRegion> regions;
	for (const ModelClass &mapped_class : spec.classes) {
		cv::Mat mask = classes(content) == mapped_class.id;
		if (cv::countNonZero(mask) == 0)
			continue;
		cv::resize(mask, mask, image, 0, 0, cv::INTER_NEAREST);
		cv::Mat labels;
		cv::Mat stats;
		cv::Mat centroids;
		const int count = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
		for (int label = 1; label < count; ++label) {
			if (stats.at<int>(label, cv::CC_STAT_AREA) < spec.min_region_px)
				continue;
			const cv::Rect r(stats.at<int>(label, cv::CC_STAT_LEFT), stats.at<int>(label, cv::CC_STAT_TOP),
					 stats.at<int>(label, cv::CC_STAT_WIDTH),
					 stats.at<int>(label, cv::CC_STAT_HEIGHT));
			PriorRegion region;
			region.box = cv::Rect2f(r);
			region.score = 1;
			region.category = mapped_class.category;
			region.class_id = mapped_class.id;
			region.mask = labels(r) == label;
			regions.push_back(std::move(region));
		}
	}
	return regions;
}

PriorModel::PriorModel(std::span<const char> onnx, PriorModelSpec spec) : spec_(std::move(spec))
{
	if (spec_.classes.empty())
		throw PriorModelError("no class is mapped to a category");
	try {
		net_ = cv::dnn::readNetFromONNX(onnx.data(), onnx.size());
	} catch (const cv::Exception &e) {
		throw PriorModelError(std::string("not a model OpenCV's dnn can read: ") + e.err);
	}
	if (net_.empty())
		throw PriorModelError("not a model OpenCV's dnn can read (empty network)");
	net_.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
	net_.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
	// One run on a blank image of the input's size: the output's shape must fit the layout.
	const cv::Mat blank(spec_.input_height, spec_.input_width, CV_8UC3, cv::Scalar::all(114));
	Letterbox box;
	cv::Mat output;
	try {
		output = run(blank, box);
	} catch (const cv::Exception &e) {
		throw PriorModelError("the network does not run on a " + std::to_string(spec_.input_width) + " x " +
				      std::to_string(spec_.input_height) + " image: " + e.err);
	}
	try {
		if (spec_.layout == ModelLayout::Segmentation) {
			decode_segmentation(output, spec_, box, blank.size());
			output_classes_ = output.dims == 4 ? output.size[1] : 0;
		} else {
			decode_detections(output, spec_, box, blank.size(), 0);
			const bool v8 = spec_.layout == ModelLayout::Yolov8;
			output_classes_ = v8 ? output.size[output.dims - 2] - 4 : output.size[output.dims - 1] - 5;
		}
	} catch (const std::runtime_error &e) {
		throw PriorModelError(e.what());
	}
	// A class number the output does not have would never be seen: say so now. (Class ids of a
	// one-channel segmentation output are values, not channels: any number may appear.)
	for (const ModelClass &c : spec_.classes)
		if (output_classes_ > 0 && c.id >= output_classes_)
			throw PriorModelError("class " + std::to_string(c.id) + " is mapped, but the model has " +
					      std::to_string(output_classes_) + " classes (0 to " +
					      std::to_string(output_classes_ - 1) + ")");
}

cv::Mat PriorModel::run(const cv::Mat &image, Letterbox &box) const
{
	cv::Mat bgr;
	if (image.channels() == 1)
		cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
	else if (image.channels() == 4)
		cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
	else
		bgr = image;
	const cv::Size input(spec_.input_width, spec_.input_height);
	box = letterbox_for(bgr.size(), input);
	// Letterbox: scaled to fit, the rest grey (114, as the YOLO exports are trained with).
	cv::Mat padded(input, CV_8UC3, cv::Scalar::all(114));
	cv::resize(bgr, padded(cv::Rect(cv::Point(0, 0), box.content)), box.content, 0, 0, cv::INTER_AREA);
	const cv::Mat blob = cv::dnn::blobFromImage(padded, spec_.input_scale, cv::Size(), cv::Scalar(), spec_.swap_rb,
						    false, CV_32F);
	const std::lock_guard lock(mutex_);
	net_.setInput(blob);
	return net_.forward().clone();
}

std::vector<PriorRegion> PriorModel::detect(const cv::Mat &image, double margin) const
{
	if (image.empty() || image.depth() != CV_8U)
		return {};
	Letterbox box;
	const cv::Mat output = run(image, box);
	if (spec_.layout == ModelLayout::Segmentation)
		return decode_segmentation(output, spec_, box, image.size());
	return decode_detections(output, spec_, box, image.size(), margin);
}

} // namespace stereod::vision
