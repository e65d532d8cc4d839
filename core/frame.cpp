#include "core/frame.hpp"

namespace stereod {

std::string_view to_string(PixelFormat format) noexcept
{
	switch (format) {
	case PixelFormat::Mono8:
		return "mono8";
	case PixelFormat::Bgr8:
		return "bgr8";
	}
	return "unknown";
}

std::string_view to_string(FrameStatus status) noexcept
{
	switch (status) {
	case FrameStatus::Ok:
		return "ok";
	case FrameStatus::Incomplete:
		return "incomplete";
	case FrameStatus::Corrupt:
		return "corrupt";
	}
	return "unknown";
}

int cv_type(PixelFormat format) noexcept
{
	return format == PixelFormat::Mono8 ? CV_8UC1 : CV_8UC3;
}

void StereoFrame::allocate(const FrameGeometry &geometry)
{
	const int type = cv_type(geometry.format);
	left.create(geometry.height, geometry.width, type);
	if (geometry.stereo)
		right.create(geometry.height, geometry.width, type);
	else
		right.release();
	if (geometry.depth)
		depth.create(geometry.height, geometry.width, CV_32FC1);
	else
		depth.release();
	if (geometry.truth)
		truth.object_ids.create(geometry.height, geometry.width, CV_8UC1);
	else
		truth.object_ids.release();
}

void StereoFrame::copy_to(StereoFrame &dst) const
{
	dst.sequence = sequence;
	dst.device_ns = device_ns;
	dst.host_ns = host_ns;
	dst.lr_skew_ns = lr_skew_ns;
	dst.status = status;
	dst.source_id = source_id;
	left.copyTo(dst.left);
	if (!right.empty())
		right.copyTo(dst.right);
	if (!depth.empty())
		depth.copyTo(dst.depth);
	if (!truth.object_ids.empty())
		truth.object_ids.copyTo(dst.truth.object_ids);
	dst.truth.camera_pose = truth.camera_pose;
	dst.truth.objects = truth.objects;
	dst.truth.object_count = truth.object_count;
}

void StereoFrame::reset_metadata() noexcept
{
	sequence = 0;
	device_ns = 0;
	host_ns = 0;
	lr_skew_ns = 0;
	status = FrameStatus::Ok;
	source_id = 0;
	truth.object_count = 0;
}

} // namespace stereod

#include "core/spsc_ring.hpp"

namespace stereod {

std::string_view to_string(OverflowPolicy policy) noexcept
{
	return policy == OverflowPolicy::DropOldest ? "drop-oldest" : "block";
}

} // namespace stereod
