// Writes the ROS bags of the command-line tests (tests/cli/bag_tests.cmake) into a folder:
// a drive of driver-like clouds and one bag for each fault of a PointCloud2.
#include <cstdio>
#include <string>

#include "bag_fixtures.hpp"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 1;
  }
  const std::string dir = argv[1];
  bagfix::write(dir + "/drive.bag", "/points",
                {bagfix::driver_cloud(1700000000, 100000000), bagfix::driver_cloud(1700000000, 200000000),
                 bagfix::driver_cloud(1700000000, 300000000)});
  bagfix::write(dir + "/organised.bag", "/points", {bagfix::organised_cloud()}, false);
  auto spoilt = [&](const char* name, auto spoil) {
    sensor_msgs::PointCloud2 m = bagfix::driver_cloud();
    spoil(m);
    bagfix::write(dir + "/" + name + ".bag", "/points", {bagfix::driver_cloud(), m});
  };
  spoilt("point_step", [](sensor_msgs::PointCloud2& m) {
    m.point_step -= 2;
    m.row_step = m.point_step * m.width;
    m.data.resize(m.row_step);
  });
  spoilt("row_step", [](sensor_msgs::PointCloud2& m) { m.row_step -= 1; });
  spoilt("bigendian", [](sensor_msgs::PointCloud2& m) { m.is_bigendian = true; });
  spoilt("data_size", [](sensor_msgs::PointCloud2& m) { m.data.push_back(0); });
  spoilt("datatype", [](sensor_msgs::PointCloud2& m) { m.fields[3].datatype = 11; });
  return 0;
}
