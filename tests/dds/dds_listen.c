/* An independent DDS subscriber for stereod's ROS 2 topics (tests/integration/dds_two_boards.sh), written in C
 * against the same IDL (daemon/dds/ros2_types.idl, compiled by idlc for this program separately), with none of
 * stereod's code: what a ROS 2 node on another machine would receive.
 *
 *   dds_listen DOMAIN SECONDS BOARD[:sensor_data]...
 *
 * A board written NAME:sensor_data is listened to best effort (a reliable reader does not match the
 * best-effort writers of a daemon with dds.qos = "sensor_data"), the others reliably, as ROS 2's default.
 *
 * Prints one JSON line per sample received on rt/stereod/<BOARD>/{odom,points,groups,status}, and one per
 * stereod topic discovered on the domain with the type name its writer announced. */
#include <dds/dds.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ros2_types.h"

#define MAX_BOARDS 8
#define MAX_SAMPLES 16

static long long stamp_ns(const builtin_interfaces_msg_dds__Time_ *t)
{
	return (long long)t->sec * 1000000000LL + t->nanosec;
}

static void print_number(double v)
{
	if (isnan(v))
		printf("null");
	else
		printf("%.9g", v);
}

static dds_entity_t reader_for(dds_entity_t participant, const dds_topic_descriptor_t *type, const char *board,
			       const char *name, int best_effort)
{
	char topic_name[256];
	snprintf(topic_name, sizeof topic_name, "rt/stereod/%s/%s", board, name);
	const dds_entity_t topic = dds_create_topic(participant, type, topic_name, NULL, NULL);
	if (topic < 0) {
		fprintf(stderr, "dds_listen: topic %s: %s\n", topic_name, dds_strretcode(topic));
		exit(1);
	}
	/* What a ROS 2 subscriber asks for: reliable (the default profile) or best effort (sensor data), keep
	 * last (deeper here, so a burst between two polls is not lost to the check). */
	dds_qos_t *qos = dds_create_qos();
	if (best_effort)
		dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
	else
		dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
	dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 100);
	const dds_entity_t reader = dds_create_reader(participant, topic, qos, NULL);
	dds_delete_qos(qos);
	if (reader < 0) {
		fprintf(stderr, "dds_listen: reader %s: %s\n", topic_name, dds_strretcode(reader));
		exit(1);
	}
	return reader;
}

int main(int argc, char **argv)
{
	if (argc < 4) {
		fprintf(stderr, "usage: dds_listen DOMAIN SECONDS BOARD...\n");
		return 2;
	}
	const int domain = atoi(argv[1]);
	const double seconds = atof(argv[2]);
	const int boards = argc - 3 > MAX_BOARDS ? MAX_BOARDS : argc - 3;
	const dds_entity_t participant = dds_create_participant((dds_domainid_t)domain, NULL, NULL);
	if (participant < 0) {
		fprintf(stderr, "dds_listen: participant: %s\n", dds_strretcode(participant));
		return 1;
	}
	const dds_entity_t publications = dds_create_reader(participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, NULL, NULL);
	dds_entity_t odom[MAX_BOARDS], points[MAX_BOARDS], groups[MAX_BOARDS], status[MAX_BOARDS];
	for (int b = 0; b < boards; ++b) {
		char *colon = strchr(argv[3 + b], ':');
		const int best_effort = colon != NULL && strcmp(colon + 1, "sensor_data") == 0;
		if (colon != NULL)
			*colon = '\0'; /* argv[3 + b] is the board's name from here on */
		const char *board = argv[3 + b];
		odom[b] = reader_for(participant, &nav_msgs_msg_dds__Odometry__desc, board, "odom", best_effort);
		points[b] =
			reader_for(participant, &sensor_msgs_msg_dds__PointCloud2__desc, board, "points", best_effort);
		groups[b] = reader_for(participant, &vision_msgs_msg_dds__Detection3DArray__desc, board, "groups",
				       best_effort);
		status[b] = reader_for(participant, &stereod_msgs_msg_dds__Status__desc, board, "status", best_effort);
	}
	void *samples[MAX_SAMPLES] = {0};
	dds_sample_info_t infos[MAX_SAMPLES];
	const dds_time_t end = dds_time() + (dds_time_t)(seconds * 1e9);
	while (dds_time() < end) {
		int n = dds_take(publications, samples, infos, MAX_SAMPLES, MAX_SAMPLES);
		for (int i = 0; i < n; ++i) {
			const dds_builtintopic_endpoint_t *e = samples[i];
			if (infos[i].valid_data && strncmp(e->topic_name, "rt/stereod/", 11) == 0)
				printf("{\"discovered\":\"%s\",\"type\":\"%s\"}\n", e->topic_name, e->type_name);
		}
		if (n > 0)
			dds_return_loan(publications, samples, n);
		for (int b = 0; b < boards; ++b) {
			const char *board = argv[3 + b];
			n = dds_take(odom[b], samples, infos, MAX_SAMPLES, MAX_SAMPLES);
			for (int i = 0; i < n; ++i) {
				if (!infos[i].valid_data)
					continue;
				const nav_msgs_msg_dds__Odometry_ *m = samples[i];
				const struct geometry_msgs_msg_dds__Pose_ *p = &m->pose.pose;
				printf("{\"board\":\"%s\",\"topic\":\"odom\",\"stamp_ns\":%lld,\"frame_id\":\"%s\","
				       "\"child_frame_id\":\"%s\",\"p\":[",
				       board, stamp_ns(&m->header.stamp), m->header.frame_id, m->child_frame_id);
				print_number(p->position.x);
				printf(",");
				print_number(p->position.y);
				printf(",");
				print_number(p->position.z);
				printf("],\"q\":[");
				print_number(p->orientation.x);
				printf(",");
				print_number(p->orientation.y);
				printf(",");
				print_number(p->orientation.z);
				printf(",");
				print_number(p->orientation.w);
				printf("],\"pose_variance\":");
				print_number(m->pose.covariance[0]);
				printf(",\"v\":[");
				print_number(m->twist.twist.linear.x);
				printf(",");
				print_number(m->twist.twist.linear.y);
				printf(",");
				print_number(m->twist.twist.linear.z);
				printf("]}\n");
			}
			if (n > 0)
				dds_return_loan(odom[b], samples, n);
			n = dds_take(points[b], samples, infos, MAX_SAMPLES, MAX_SAMPLES);
			for (int i = 0; i < n; ++i) {
				if (!infos[i].valid_data)
					continue;
				const sensor_msgs_msg_dds__PointCloud2_ *m = samples[i];
				printf("{\"board\":\"%s\",\"topic\":\"points\",\"stamp_ns\":%lld,\"frame_id\":\"%s\","
				       "\"width\":%u,\"point_step\":%u,\"fields\":[",
				       board, stamp_ns(&m->header.stamp), m->header.frame_id, m->width, m->point_step);
				for (uint32_t f = 0; f < m->fields._length; ++f)
					printf("%s[\"%s\",%u,%u]", f ? "," : "", m->fields._buffer[f].name,
					       m->fields._buffer[f].offset, m->fields._buffer[f].datatype);
				/* The labels and the first point, read by the fields' offsets as a ROS 2 tool would. */
				printf("],\"labels\":\"");
				for (uint32_t k = 0; k < m->width && (k + 1) * m->point_step <= m->data._length; ++k)
					putchar("sdu"[m->data._buffer[k * m->point_step + 20] % 3]);
				printf("\",\"first\":[");
				for (int c = 0; c < 5 && m->width > 0 && m->point_step * m->width <= m->data._length;
				     ++c) {
					float v;
					memcpy(&v, m->data._buffer + 4 * c, 4);
					if (c)
						printf(",");
					print_number(v);
				}
				printf("]}\n");
			}
			if (n > 0)
				dds_return_loan(points[b], samples, n);
			n = dds_take(groups[b], samples, infos, MAX_SAMPLES, MAX_SAMPLES);
			for (int i = 0; i < n; ++i) {
				if (!infos[i].valid_data)
					continue;
				const vision_msgs_msg_dds__Detection3DArray_ *m = samples[i];
				printf("{\"board\":\"%s\",\"topic\":\"groups\",\"stamp_ns\":%lld,\"detections\":[",
				       board, stamp_ns(&m->header.stamp));
				for (uint32_t d = 0; d < m->detections._length; ++d) {
					const vision_msgs_msg_dds__Detection3D_ *det = &m->detections._buffer[d];
					printf("%s{\"id\":\"%s\",\"class\":\"%s\",\"center\":[", d ? "," : "", det->id,
					       det->results._length > 0 ? det->results._buffer[0].hypothesis.class_id
									: "");
					print_number(det->bbox.center.position.x);
					printf(",");
					print_number(det->bbox.center.position.y);
					printf(",");
					print_number(det->bbox.center.position.z);
					printf("]}");
				}
				printf("]}\n");
			}
			if (n > 0)
				dds_return_loan(groups[b], samples, n);
			n = dds_take(status[b], samples, infos, MAX_SAMPLES, MAX_SAMPLES);
			for (int i = 0; i < n; ++i) {
				if (!infos[i].valid_data)
					continue;
				const stereod_msgs_msg_dds__Status_ *m = samples[i];
				printf("{\"board\":\"%s\",\"topic\":\"status\",\"name\":\"%s\",\"source\":\"%s\","
				       "\"source_state\":\"%s\",\"fps_publish\":%.3f,\"frames_published\":%llu,"
				       "\"drops\":%llu,\"latency_p99_ms\":%.3f,\"groups_in_view\":%u}\n",
				       board, m->name, m->source, m->source_state, m->fps_publish,
				       (unsigned long long)m->frames_published, (unsigned long long)m->drops,
				       m->latency_p99_ms, m->groups_in_view);
			}
			if (n > 0)
				dds_return_loan(status[b], samples, n);
		}
		fflush(stdout);
		dds_sleepfor(DDS_MSECS(5));
	}
	dds_delete(participant);
	return 0;
}
