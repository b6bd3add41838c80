# The lex3d command on ROS bags: info, compress, decompress and convert to and from bags,
# and the bad inputs (a missing topic, inconsistent PointCloud2 fields, a truncated bag):
# exit 2, one line naming the file, no output written.
# Run by CTest as: cmake -DLEX3D=... -DMAKE_BAGS=... -DSHARED=... -DWORK=... -P bag_tests.cmake

file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")
execute_process(COMMAND "${MAKE_BAGS}" "${WORK}" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cannot write the test bags (${rc})")
endif()

include("${CMAKE_CURRENT_LIST_DIR}/cli_common.cmake")

function(expect_absent name)
  foreach(f ${ARGN})
    if(EXISTS "${f}")
      message(SEND_ERROR "[${name}] ${f} was written")
    endif()
  endforeach()
  file(GLOB tmp "${WORK}/.lex3d-*")
  if(tmp)
    message(SEND_ERROR "[${name}] temporary files left: ${tmp}")
  endif()
endfunction()

set(DRIVE "${WORK}/drive.bag")

# --- info lists the topics
run(0 info.topics info "${DRIVE}")
expect_match(info.topics "${LAST_OUT}" "/points +sensor_msgs/PointCloud2 +3 messages")
expect_match(info.topics "${LAST_OUT}" "/note +std_msgs/String +1 messages")
run(0 info.json info --json "${DRIVE}")
expect_match(info.json "${LAST_OUT}" "\"topic\":\"/points\",\"type\":\"sensor_msgs/PointCloud2\",\"messages\":3")

# --- compress: one scan a message, names from the stamps; the reflectivity field is kept by name
run(0 compress.bag compress "${DRIVE}" --topic /points -o "${WORK}/drive.lex3dq" --one-file)
expect_match(compress.bag "${LAST_OUT}" "total: [0-9]+ bytes for 1200 points")
expect_match(compress.bag "${LAST_OUT}" "kept reflectivity")
expect_match(compress.bag "${LAST_OUT}" "kept intensity")
expect_match(compress.bag "${LAST_OUT}" "kept time")
run(0 compress.default_topic compress "${DRIVE}" -o "${WORK}/drive_default.lex3dq" --one-file)

# --- decompress into a bag (one message a scan, stamped as read) and read it again
run(0 decompress.bag decompress "${WORK}/drive.lex3dq" -o "${WORK}/back.bag")
run(0 info.back info "${WORK}/back.bag")
expect_match(info.back "${LAST_OUT}" "/points +sensor_msgs/PointCloud2 +3 messages")
expect_match(info.back "${LAST_OUT}" "messages +3 over 0.200 s")
run(0 decompress.pcd decompress "${WORK}/drive.lex3dq" -o "${WORK}/back.pcd")
expect_match(decompress.pcd "${LAST_OUT}" "back_drive_1700000000.100000000.pcd")
run(0 compress.again compress "${WORK}/back.bag" -o "${WORK}/again.lex3dq" --one-file)
expect_match(compress.again "${LAST_OUT}" "total: [0-9]+ bytes for 1200 points")

# --- convert: a bag to clouds and clouds into one bag; an organised cloud stays organised
run(0 convert.organised convert "${WORK}/organised.bag" "${WORK}/organised.pcd")
expect_match(convert.organised "${LAST_OUT}" "30 points \\(4 x 8 organised\\)")
run(0 convert.to_bag convert "${DRIVE}" "${WORK}/copy.bag")
run(0 info.copy info --json "${WORK}/copy.bag")
expect_match(info.copy "${LAST_OUT}" "\"messages\":3")

# --- bad input: exit 2, one line naming the file, nothing written
run(2 bad.topic compress "${DRIVE}" --topic /velodyne_points -o "${WORK}/x.lex3dq" --one-file)
expect_match(bad.topic "${LAST_ERR}" "drive.bag: no topic '/velodyne_points' in the bag; it holds /note \\(std_msgs/String, 1\\), /points \\(sensor_msgs/PointCloud2, 3\\)")
expect_absent(bad.topic "${WORK}/x.lex3dq")
run(2 bad.topic_type compress "${DRIVE}" --topic /note -o "${WORK}/x.lex3dq" --one-file)
expect_match(bad.topic_type "${LAST_ERR}" "/note holds std_msgs/String messages")
foreach(case point_step row_step bigendian data_size datatype)
  run(2 bad.${case} compress "${WORK}/${case}.bag" -o "${WORK}/${case}.lex3dq" --one-file)
  expect_match(bad.${case} "${LAST_ERR}" "${case}.bag: message 1 on /points: ")
  expect_absent(bad.${case} "${WORK}/${case}.lex3dq")
endforeach()
expect_match(bad.datatype "${LAST_ERR}" "unknown datatype 11")
run(2 bad.convert convert "${WORK}/row_step.bag" "${WORK}/row_step.pcd")
expect_absent(bad.convert "${WORK}/row_step.pcd")

execute_process(COMMAND head -c 6000 "${DRIVE}" OUTPUT_FILE "${WORK}/truncated.bag")
run(2 bad.truncated compress "${WORK}/truncated.bag" -o "${WORK}/truncated.lex3dq" --one-file)
expect_match(bad.truncated "${LAST_ERR}" "truncated.bag: .*(truncated|corrupt)")
expect_absent(bad.truncated "${WORK}/truncated.lex3dq")
run(2 bad.truncated_info info "${WORK}/truncated.bag")
file(WRITE "${WORK}/fake.bag" "#ROSBAG V2.0\nnothing else\n")
run(2 bad.fake info "${WORK}/fake.bag")
expect_match(bad.fake "${LAST_ERR}" "fake.bag: ")

# --- compressed chunks: bz2 and LZ4 bags read as the uncompressed one; a chunk that declares
# another size than it decompresses to, or whose compressed bytes are spoilt, is named
foreach(c bz2 lz4)
  run(0 packed.${c} compress "${WORK}/packed_${c}.bag" -o "${WORK}/packed_${c}.lex3dq" --one-file)
  expect_match(packed.${c} "${LAST_OUT}" "total: [0-9]+ bytes for 800 points")
  foreach(what size flip)
    set(bag "${WORK}/chunk_${what}_${c}.bag")
    run(2 chunk.${what}.${c} compress "${bag}" -o "${WORK}/chunk_${what}_${c}.lex3dq" --one-file)
    expect_match(chunk.${what}.${c} "${LAST_ERR}" "chunk_${what}_${c}.bag: corrupt bag: chunk 1 at byte [0-9]+ \\(${c}, [0-9]+ bytes\\) ")
    expect_absent(chunk.${what}.${c} "${WORK}/chunk_${what}_${c}.lex3dq")
    if(what STREQUAL "size")
      expect_match(chunk.size.${c} "${LAST_ERR}" "decompresses to [0-9]+ bytes, fewer than the [0-9]+ its header declares")
    endif()
    run(2 chunk.${what}.${c}.convert convert "${bag}" "${WORK}/chunk_${what}_${c}.pcd")
    expect_absent(chunk.${what}.${c}.convert "${WORK}/chunk_${what}_${c}.pcd" "${WORK}/chunk_${what}_${c}_000.pcd")
  endforeach()
endforeach()

# --- the shared Ouster bag (raw packets + metadata), when the data set is present
set(OUSTER "${SHARED}/rosbag/ouster_512x10_raw.bag")
if(EXISTS "${OUSTER}")
  run(0 ouster.info info "${OUSTER}")
  expect_match(ouster.info "${LAST_OUT}" "/os_node0/lidar_packets +ouster_ros/PacketMsg +32 messages")
  run(0 ouster.compress compress "${OUSTER}" -o "${WORK}/ouster.lex3dq" --one-file --json)
  expect_match(ouster.compress "${LAST_OUT}" "\"source\":\"metadata\",\"lasers\":128,\"columns\":512")
  run(0 ouster.convert convert "${OUSTER}" "${WORK}/ouster.pcd")
  expect_match(ouster.convert "${LAST_OUT}" "\\(128 x 512 organised\\)")
else()
  message(STATUS "[ouster] skipped: no ${OUSTER}")
endif()


# --- without the ROS bag plugin (LEX3D_ROSBAG_PLUGIN naming a missing file, then a file that
# is not a shared library): every bag command fails with one line naming the bag, exit 2,
# nothing written; other formats still work
set(ENV{LEX3D_ROSBAG_PLUGIN} "${WORK}/no_such_dir/liblex3d_rosbag.so")
run(2 noplugin.info info "${DRIVE}")
expect_match(noplugin.info "${LAST_ERR}" "drive.bag: ROS bag support is not installed \\(.*no_such_dir/liblex3d_rosbag.so, named by LEX3D_ROSBAG_PLUGIN, not found\\)")
run(2 noplugin.compress compress "${DRIVE}" -o "${WORK}/noplugin.lex3dq" --one-file)
expect_match(noplugin.compress "${LAST_ERR}" "drive.bag: ROS bag support is not installed")
expect_absent(noplugin.compress "${WORK}/noplugin.lex3dq")
run(2 noplugin.decompress decompress "${WORK}/drive.lex3dq" -o "${WORK}/noplugin.bag")
expect_match(noplugin.decompress "${LAST_ERR}" "noplugin.bag: ROS bag support is not installed")
expect_absent(noplugin.decompress "${WORK}/noplugin.bag")
run(0 noplugin.pcd decompress "${WORK}/drive.lex3dq" -o "${WORK}/noplugin.pcd")
file(WRITE "${WORK}/not_a_plugin.so" "not a shared library\n")
set(ENV{LEX3D_ROSBAG_PLUGIN} "${WORK}/not_a_plugin.so")
run(2 badplugin.info info "${DRIVE}")
expect_match(badplugin.info "${LAST_ERR}" "drive.bag: ROS bag support cannot be loaded \\(.*not_a_plugin.so: ")
unset(ENV{LEX3D_ROSBAG_PLUGIN})

# --- a raw capture's turns are stamped with their capture time (the pcap record of the
# turn's first packet): converted to a bag, and through a sequence file decompressed to one
set(VLP16 "${SAMPLES}/vlp16_velodyne_example.pcap")
run(0 capture.stamp_convert convert "${VLP16}" "${WORK}/v_stamped.bag")
expect_match(capture.stamp_convert "${LAST_OUT}" "turn 0 \\(frame 0, captured 1525347606\\.362040000\\)")
run(0 capture.stamp_convert_info info "${WORK}/v_stamped.bag" --json)
expect_match(capture.stamp_convert_info "${LAST_OUT}" "\"start_s\":1525347606[,.]")
run(0 capture.stamp_sequence compress "${VLP16}" -o "${WORK}/v_stamped.lex3dq" --one-file --max-error 0.02)
run(0 capture.stamp_sequence_back decompress "${WORK}/v_stamped.lex3dq" -o "${WORK}/v_stamped_back.bag")
run(0 capture.stamp_sequence_info info "${WORK}/v_stamped_back.bag" --json)
expect_match(capture.stamp_sequence_info "${LAST_OUT}" "\"start_s\":1525347606[,.]")

# --- a single model file keeps its scan's stamp and frame (the optional `scan` chunk): a
# turn's capture time, a message's stamp and frame_id, back into a bag; a format that holds
# neither says so
run(0 stamp.capture_model compress "${VLP16}" -o "${WORK}/v_single.lex3dm" --max-error 0.02)
run(0 stamp.capture_info info "${WORK}/v_single.lex3dm")
expect_match(stamp.capture_info "${LAST_OUT}" "scan stamp +1525347606\\.362040000 \\(capture time of its first packet\\)")
run(0 stamp.capture_bag decompress "${WORK}/v_single.lex3dm" -o "${WORK}/v_single.bag")
run(0 stamp.capture_bag_info info "${WORK}/v_single.bag" --json)
expect_match(stamp.capture_bag_info "${LAST_OUT}" "\"start_s\":1525347606[,.]")
run(0 stamp.capture_pcd decompress "${WORK}/v_single.lex3dm" -o "${WORK}/v_single.pcd")
expect_match(stamp.capture_pcd "${LAST_ERR}" "v_single.pcd: the scan's stamp \\(capture time of its first packet, 1525347606\\.362040000\\) not written")
run(0 stamp.message_models compress "${DRIVE}" --topic /points -o "${WORK}/m.lex3dm")
run(0 stamp.message_info info "${WORK}/m_001.lex3dm" --json)
expect_match(stamp.message_info "${LAST_OUT}" "\"stamp\":\\{\"sec\":1700000000,\"nsec\":200000000,\"text\":\"1700000000\\.200000000\",\"source\":\"message\",\"frame_id\":\"lidar\"\\}")
run(0 stamp.message_bag decompress "${WORK}/m_001.lex3dm" -o "${WORK}/m_001.bag")
run(0 stamp.message_again compress "${WORK}/m_001.bag" -o "${WORK}/m_again.lex3dm")
run(0 stamp.message_again_info info "${WORK}/m_again.lex3dm")
expect_match(stamp.message_again_info "${LAST_OUT}" "scan stamp +1700000000\\.200000000 \\(message stamp\\), frame lidar")

# --- Velodyne packets recorded as velodyne_driver records them (velodyne_msgs/VelodyneScan):
# each turn a scan named and stamped after its first packet, through a sequence file and back
set(VBAG "${SAMPLES}/../tests/fuzz/readers/bag/velodyne_packets_lz4.bag")
run(0 velodyne.info info "${VBAG}")
expect_match(velodyne.info "${LAST_OUT}" "/velodyne_packets +velodyne_msgs/VelodyneScan +4 messages")
run(0 velodyne.compress compress "${VBAG}" -o "${WORK}/vbag.lex3dq" --one-file --max-error 0.02)
expect_match(velodyne.compress "${LAST_OUT}" "/velodyne_packets frame 1 \\(stamp 1700000000\\.005529600\\)")
run(0 velodyne.back decompress "${WORK}/vbag.lex3dq" -o "${WORK}/vbag_back.bag")
run(0 velodyne.back_info info "${WORK}/vbag_back.bag")
expect_match(velodyne.back_info "${LAST_OUT}" "messages +2 over 0\\.006 s")
