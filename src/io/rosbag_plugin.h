/* The interface between io (rosbag.cpp) and the ROS bag plugin liblex3d_rosbag.so
 * (rosbag_plugin.cpp), the one part of lex3d that calls the ROS libraries. io opens the
 * plugin with dlopen on the first bag it reads or writes, so that liblex3d.so, the command
 * and the Python module do not load librosbag_storage, boost and the rest at start-up.
 *
 * The plugin does the bag container work only (open, list the connections, hand over each
 * message's serialized bytes, write a PointCloud2); io parses the bytes itself, every length
 * checked. The interface is C: plain structs, pointers and lengths, no C++ type and no
 * exception crosses it, so that a plugin and a library built by different compilers or
 * standard libraries still fit. LEX3D_ROSBAG_ABI changes with any change to this file;
 * io refuses a plugin of another ABI. Not installed. */
#ifndef LEX3D_IO_ROSBAG_PLUGIN_H
#define LEX3D_IO_ROSBAG_PLUGIN_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define LEX3D_ROSBAG_ABI 1u
/* The plugin's one exported symbol: a function returning its table. */
#define LEX3D_ROSBAG_ENTRY "lex3d_rosbag_plugin_v1"

/* Every function returns one of these. */
enum {
  LEX3D_BAG_OK = 0,
  LEX3D_BAG_ERROR = 1,     /* the ROS bag library refused: lex3d_bag_error holds its message */
  LEX3D_BAG_NO_MEMORY = 2, /* out of memory */
  LEX3D_BAG_STOPPED = 3    /* the message callback returned non-zero */
};

/* The library's message, NUL-terminated (cut to fit). */
typedef struct {
  char text[256];
} lex3d_bag_error;

typedef struct lex3d_bag lex3d_bag; /* an open bag, owned by the plugin */

typedef struct {
  uint32_t sec, nsec;
} lex3d_bag_time;

/* One connection of a bag (a topic can have several). Valid until the bag is closed. */
typedef struct {
  const char* topic;
  const char* datatype; /* e.g. "sensor_msgs/PointCloud2" */
  const char* md5sum;
} lex3d_bag_connection;

/* Called with each message of a topic in bag time order: its time and its serialized bytes
 * (valid during the call). Non-zero stops the reading (LEX3D_BAG_STOPPED). */
typedef int (*lex3d_bag_message_fn)(void* user, lex3d_bag_time time, const uint8_t* bytes, size_t size);

/* A sensor_msgs/PointCloud2 to write (sensor_msgs/PointField: name offset datatype count). */
typedef struct {
  const char* name;
  uint32_t offset;
  uint8_t datatype;
  uint32_t count;
} lex3d_bag_point_field;

typedef struct {
  lex3d_bag_time stamp;
  const char* frame_id;
  uint32_t height, width;
  const lex3d_bag_point_field* fields;
  size_t field_count;
  uint8_t is_bigendian;
  uint32_t point_step, row_step;
  const uint8_t* data;
  size_t data_size;
  uint8_t is_dense;
} lex3d_bag_pointcloud2;

typedef struct {
  uint32_t abi;        /* LEX3D_ROSBAG_ABI */
  uint32_t table_size; /* sizeof(lex3d_rosbag_plugin) */
  const char* pointcloud2_md5; /* sensor_msgs/PointCloud2's MD5 sum as the plugin writes it */
  /* Opens `path` (read: an existing bag 2.0 file; write: a new file, uncompressed chunks). */
  int (*open_read)(const char* path, lex3d_bag** bag, lex3d_bag_error* err);
  int (*open_write)(const char* path, lex3d_bag** bag, lex3d_bag_error* err);
  /* The connections of a bag opened for reading. */
  int (*connections)(lex3d_bag* bag, const lex3d_bag_connection** list, size_t* count, lex3d_bag_error* err);
  /* The number of messages on `topic`. */
  int (*count)(lex3d_bag* bag, const char* topic, uint64_t* messages, lex3d_bag_error* err);
  /* The first and last message times of the bag (both 0 when it holds none). */
  int (*time_range)(lex3d_bag* bag, lex3d_bag_time* begin, lex3d_bag_time* end, lex3d_bag_error* err);
  /* Every message on `topic`, in bag time order, to `fn`. */
  int (*read_topic)(lex3d_bag* bag, const char* topic, lex3d_bag_message_fn fn, void* user, lex3d_bag_error* err);
  /* Writes one PointCloud2 message on `topic` at `time` (a bag opened for writing). */
  int (*write_pointcloud2)(lex3d_bag* bag, const char* topic, lex3d_bag_time time, const lex3d_bag_pointcloud2* msg,
                           lex3d_bag_error* err);
  /* Closes (a written bag: writes its index) and frees `bag`, whatever the result. */
  int (*close)(lex3d_bag* bag, lex3d_bag_error* err);
} lex3d_rosbag_plugin;

typedef const lex3d_rosbag_plugin* (*lex3d_rosbag_entry_fn)(void);

#ifdef __cplusplus
}
#endif

#endif /* LEX3D_IO_ROSBAG_PLUGIN_H */
