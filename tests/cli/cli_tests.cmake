# End-to-end checks of the lex3d command: exit codes (0 ok, 1 usage, 2 bad data,
# 3 I/O), one-line errors, no partial outputs, inputs never overwritten.
# Run by CTest as: cmake -DLEX3D=... -DSAMPLES=... -DWORK=... -P cli_tests.cmake

file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")
set(failures 0)

# run(<expected exit> <name> args...): runs lex3d, checks the exit code and, on
# failure, that stderr is exactly one line starting with "lex3d: ".
function(run expected name)
  execute_process(COMMAND "${LEX3D}" ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err
                  TIMEOUT 120)
  set(LAST_OUT "${out}" PARENT_SCOPE)
  set(LAST_ERR "${err}" PARENT_SCOPE)
  if(NOT "${rc}" STREQUAL "${expected}")
    message(SEND_ERROR "[${name}] exit ${rc}, expected ${expected}\nstdout: ${out}\nstderr: ${err}")
    return()
  endif()
  if(NOT expected EQUAL 0)
    string(REGEX MATCHALL "\n" newlines "${err}")
    list(LENGTH newlines n)
    if(NOT n EQUAL 1 OR NOT err MATCHES "^lex3d: ")
      message(SEND_ERROR "[${name}] stderr is not one 'lex3d: ...' line: '${err}'")
    endif()
  endif()
  message(STATUS "[${name}] ok (exit ${rc})")
endfunction()

function(expect_match name text regex)
  if(NOT "${text}" MATCHES "${regex}")
    message(SEND_ERROR "[${name}] output does not match '${regex}':\n${text}")
  endif()
endfunction()

set(KITTI "${SAMPLES}/kitti00_000000.bin")

# --- success paths ---
run(0 info.kitti info "${KITTI}")
expect_match(info.kitti "${LAST_OUT}" "points +124668")
run(0 info.json info --json "${SAMPLES}/room_scan1.pcd")
expect_match(info.json "${LAST_OUT}" "\"points\":112586")
expect_match(info.json "${LAST_OUT}" "\"format\":\"pcd\"")
run(0 info.binxyz info --json "${SAMPLES}/newer_college_00.bin")
expect_match(info.binxyz "${LAST_OUT}" "\"format\":\"binxyz\"")
run(0 features.png features "${KITTI}" --png "${WORK}/kitti.png")
expect_match(features.png "${LAST_OUT}" "interest points +[0-9]+")
if(NOT EXISTS "${WORK}/kitti.png")
  message(SEND_ERROR "[features.png] no PNG written")
endif()
run(0 features.json features --json "${SAMPLES}/newer_college_00.bin")
expect_match(features.json "${LAST_OUT}" "\"coverage_points\":[1-9]")
run(0 help --help)
run(0 version --version)

# --- usage errors: exit 1 ---
run(1 usage.nosub)
run(1 usage.unknown frobnicate)
run(1 usage.unknown_near compres "${KITTI}")
expect_match(usage.unknown_near "${LAST_ERR}" "unknown command 'compres'; did you mean 'compress'")
run(1 usage.format info --format nope "${KITTI}")
run(1 usage.threshold features "${KITTI}" --threshold 7)
run(1 usage.up features "${KITTI}" --up 1,2)
# An output that names the input is refused, and the input survives.
file(COPY "${KITTI}" DESTINATION "${WORK}")
file(SIZE "${WORK}/kitti00_000000.bin" size_before)
run(1 usage.overwrite features "${WORK}/kitti00_000000.bin" --png "${WORK}/kitti00_000000.bin")
file(SIZE "${WORK}/kitti00_000000.bin" size_after)
if(NOT size_before EQUAL size_after)
  message(SEND_ERROR "[usage.overwrite] the input was modified")
endif()

# --- bad data: exit 2 ---
run(2 bad.missing info "${WORK}/does_not_exist.pcd")
expect_match(bad.missing "${LAST_ERR}" "does_not_exist.pcd")
file(WRITE "${WORK}/empty.bin" "")
run(2 bad.empty info "${WORK}/empty.bin")
file(WRITE "${WORK}/odd.bin" "0123456789abcdefg")
run(2 bad.odd info "${WORK}/odd.bin")
file(WRITE "${WORK}/garbage.xyz" "1 2 3\n4 five 6\n")
run(2 bad.text info "${WORK}/garbage.xyz")
file(WRITE "${WORK}/broken.pcd" "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\nHEIGHT 1\nPOINTS 1000\nDATA binary\nabc")
run(2 bad.truncated features "${WORK}/broken.pcd")
run(2 bad.truncated_png features "${WORK}/broken.pcd" --png "${WORK}/broken.png")
if(EXISTS "${WORK}/broken.png")
  message(SEND_ERROR "[bad.truncated_png] an output was written for bad input")
endif()

# --- I/O errors: exit 3, no partial file ---
run(3 io.nodir features "${SAMPLES}/newer_college_00.bin" --png "${WORK}/no/such/dir/out.png")
file(GLOB leftovers "${WORK}/no/such/dir/*")
if(leftovers)
  message(SEND_ERROR "[io.nodir] left files behind: ${leftovers}")
endif()

# --- an empty cloud is handled, not a crash ---
file(WRITE "${WORK}/empty.pcd" "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\nHEIGHT 1\nPOINTS 0\nDATA ascii\n")
run(0 empty.info info "${WORK}/empty.pcd")
run(0 empty.features features "${WORK}/empty.pcd")

# --- learn / reconstruct ---
set(NC "${SAMPLES}/newer_college_00.bin")
run(0 learn.small learn "${NC}" -o "${WORK}/nc.alpha" --iterations 30 --json)
expect_match(learn.small "${LAST_OUT}" "\"words\":[0-9]+")
expect_match(learn.small "${LAST_OUT}" "\"bic_history\":\\[")
run(0 reconstruct.reuse reconstruct "${NC}" --alphabet "${WORK}/nc.alpha" -o "${WORK}/nc_rec.ply" --json)
expect_match(reconstruct.reuse "${LAST_OUT}" "\"compression_rate\":0\\.[0-9]+")
expect_match(reconstruct.reuse "${LAST_OUT}" "\"inliers\":0\\.[0-9]+")
if(NOT EXISTS "${WORK}/nc_rec.ply")
  message(SEND_ERROR "[reconstruct.reuse] no reconstruction written")
endif()
run(1 learn.overwrite learn "${NC}" -o "${NC}")
file(WRITE "${WORK}/garbage.alpha" "L3DA not really an alphabet")
run(2 reconstruct.bad_alphabet reconstruct "${NC}" --alphabet "${WORK}/garbage.alpha" -o "${WORK}/never.ply")
if(EXISTS "${WORK}/never.ply")
  message(SEND_ERROR "[reconstruct.bad_alphabet] an output was written")
endif()

# --- compress / decompress / info on model files ---
run(0 compress.learn compress "${NC}" -o "${WORK}/nc.lex3dm" --iterations 30 --json)
expect_match(compress.learn "${LAST_OUT}" "\"bits_per_point\":[0-9]")
run(0 info.model info "${WORK}/nc.lex3dm")
expect_match(info.model "${LAST_OUT}" "lex3d model, format 1\\.0")
expect_match(info.model "${LAST_OUT}" "INST")
run(0 decompress.ply decompress "${WORK}/nc.lex3dm" -o "${WORK}/nc_dec.ply" --reference "${NC}" --json)
expect_match(decompress.ply "${LAST_OUT}" "\"d1_psnr_db\":[0-9]")
run(0 decompress.octomap decompress "${WORK}/nc.lex3dm" --octomap "${WORK}/nc.bt" --resolution 0.25)
if(NOT EXISTS "${WORK}/nc.bt")
  message(SEND_ERROR "[decompress.octomap] no OctoMap written")
endif()
# A map has no one viewpoint: only the occupied voxels.
run(0 decompress.octomap_map decompress "${WORK}/nc.lex3dm" --octomap "${WORK}/nc_map.bt" --resolution 0.25 --free-space none)
expect_match(decompress.octomap_map "${LAST_OUT}" " 0 free leaves")
run(1 decompress.octomap_bad_free decompress "${WORK}/nc.lex3dm" --octomap "${WORK}/nc_bad.bt" --free-space some)
# Alphabet reuse: a learned alphabet file, models that reference it.
run(0 compress.save compress "${NC}" -o "${WORK}/nc_ref.lex3dm" --save-alphabet "${WORK}/nc.lex3da" --iterations 30)
run(0 info.alphabet info --json "${WORK}/nc.lex3da")
expect_match(info.alphabet "${LAST_OUT}" "\"kind\":\"alphabet\"")
expect_match(info.alphabet "${LAST_OUT}" "\"word_radius_m\":[0-9]")
set(ALPHABET_INFO "${LAST_OUT}")
run(0 compress.reuse compress "${NC}" -o "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/nc.lex3da")
run(2 decompress.no_alphabet decompress "${WORK}/nc_reuse.lex3dm" -o "${WORK}/x.ply")
expect_match(decompress.no_alphabet "${LAST_ERR}" "--alphabet")
run(0 decompress.with_alphabet decompress "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/nc.lex3da" -o "${WORK}/nc_reuse.ply")
# info on a model that references its alphabet: the chunks without it, the counts with it.
run(0 info.referenced info "${WORK}/nc_reuse.lex3dm")
expect_match(info.referenced "${LAST_OUT}" "referenced by hash")
if("${LAST_OUT}" MATCHES "instances")
  message(SEND_ERROR "[info.referenced] counts printed without the alphabet:\n${LAST_OUT}")
endif()
run(0 info.with_alphabet info --json "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/nc.lex3da")
expect_match(info.with_alphabet "${LAST_OUT}" "\"instances\":[1-9]")
expect_match(info.with_alphabet "${LAST_OUT}" "\"input_points\":[1-9]")
# Instance steps: by default the word radius / 32 and 1/32 rad; given ones are kept.
# (codec tests check the formula; CMake has no floating-point arithmetic to redo it here)
string(JSON nc_radius GET "${ALPHABET_INFO}" word_radius_m)
string(JSON nc_tstep GET "${LAST_OUT}" translation_step_m)
string(JSON nc_rstep GET "${LAST_OUT}" rotation_step_rad)
if(NOT nc_rstep STREQUAL "0.03125" OR NOT nc_tstep MATCHES "^0\\.0[0-9]+$" OR nc_tstep STREQUAL "0.002")
  message(SEND_ERROR "[steps.default] steps ${nc_tstep} m / ${nc_rstep} rad for a word radius of ${nc_radius} m")
endif()
run(0 compress.steps compress "${NC}" -o "${WORK}/nc_steps.lex3dm" --alphabet "${WORK}/nc.lex3da" --translation-step 0.002 --rotation-step 0.001)
run(0 info.steps info --json "${WORK}/nc_steps.lex3dm" --alphabet "${WORK}/nc.lex3da")
expect_match(info.steps "${LAST_OUT}" "\"translation_step_m\":0\\.002,\"rotation_step_rad\":0\\.001")
run(1 usage.rotation_step compress "${NC}" -o "${WORK}/never.lex3dm" --alphabet "${WORK}/nc.lex3da" --rotation-step 0.5)
# A wrong alphabet is bad data; a corrupt model is bad data; no partial outputs.
run(0 learn.other learn "${SAMPLES}/room_scan1.pcd" -o "${WORK}/other.lex3da" --iterations 10)
run(2 decompress.wrong_alphabet decompress "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/other.lex3da" -o "${WORK}/y.ply")
run(2 info.wrong_alphabet info "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/other.lex3da")
# Truncated and corrupt model files are covered byte by byte in test_codec; here a
# file that is not a model at all.
run(2 decompress.garbage decompress "${WORK}/garbage.alpha" -o "${WORK}/z.ply")
if(EXISTS "${WORK}/y.ply" OR EXISTS "${WORK}/z.ply" OR EXISTS "${WORK}/x.ply")
  message(SEND_ERROR "[decompress] an output was written for bad input")
endif()
run(1 compress.overwrite compress "${NC}" -o "${NC}")
# Without ICP fitting the instance poses are the feature frames as built (in float); the
# room scan has some whose rotation was not orthonormal enough for the file format.
run(0 compress.no_icp compress "${SAMPLES}/room_scan1.pcd" -o "${WORK}/room_noicp.lex3dm" --iterations 10 --refine-iterations 0)

# --- the residual layer: --max-error, --target-bpp, --words ---
run(0 compress.layer compress "${NC}" -o "${WORK}/nc_e.lex3dm" --max-error 0.02 --words off --json)
expect_match(compress.layer "${LAST_OUT}" "\"max_error_m\":0\\.02")
run(0 info.layer info "${WORK}/nc_e.lex3dm")
expect_match(info.layer "${LAST_OUT}" "residual layer max error 0\\.02 m")
run(0 decompress.layer decompress "${WORK}/nc_e.lex3dm" -o "${WORK}/nc_e.ply" --reference "${NC}" --json)
expect_match(decompress.layer "${LAST_OUT}" "\"residual_layer\":true")
# The bound holds both ways: the Hausdorff distance is at most 2 cm (printed as 0.0nnn).
expect_match(decompress.layer "${LAST_OUT}" "\"hausdorff_m\":(0\\.01[0-9]*|0\\.00[0-9]*|0\\.020*[,}]|[0-9.]+e-)")
run(0 compress.layer_words compress "${NC}" -o "${WORK}/nc_ew.lex3dm" --max-error 0.1 --words auto --iterations 20 --json)
expect_match(compress.layer_words "${LAST_OUT}" "\"words_used\":(true|false)")
run(0 compress.target compress "${NC}" -o "${WORK}/nc_t.lex3dm" --target-bpp 8 --words off --json)
expect_match(compress.target "${LAST_OUT}" "\"bits_per_point\":([0-7]\\.|8\\.0*[,}])")
# The voxel coding, forced: a format 1.3 file whose decoded cloud meets the bound.
run(0 compress.voxel compress "${NC}" -o "${WORK}/nc_v.lex3dm" --max-error 0.02 --layer-coding voxel --json)
expect_match(compress.voxel "${LAST_OUT}" "\"coding\":\"voxel\"")
run(0 info.voxel info "${WORK}/nc_v.lex3dm")
expect_match(info.voxel "${LAST_OUT}" "format 1\\.3")
expect_match(info.voxel "${LAST_OUT}" "RESV")
expect_match(info.voxel "${LAST_OUT}" "voxel coding")
run(0 decompress.voxel decompress "${WORK}/nc_v.lex3dm" -o "${WORK}/nc_v.ply" --reference "${NC}" --json)
expect_match(decompress.voxel "${LAST_OUT}" "\"hausdorff_m\":(0\\.01[0-9]*|0\\.00[0-9]*|0\\.020*[,}]|[0-9.]+e-)")
run(0 compress.spherical compress "${NC}" -o "${WORK}/nc_s.lex3dm" --max-error 0.02 --layer-coding spherical --json)
expect_match(compress.spherical "${LAST_OUT}" "\"coding\":\"(previous-point|sweep)\"")
# The sensor-geometry coding, forced on the KITTI sample (its lasers estimated from the
# points): a format 1.4 file whose decoded cloud meets the bound.
run(0 compress.laser compress "${KITTI}" -o "${WORK}/k_l.lex3dm" --max-error 0.02 --layer-coding laser --json)
expect_match(compress.laser "${LAST_OUT}" "\"coding\":\"sensor-geometry\"")
expect_match(compress.laser "${LAST_OUT}" "\"laser_table\":{\"source\":\"estimated")
run(0 info.laser info "${WORK}/k_l.lex3dm")
expect_match(info.laser "${LAST_OUT}" "format 1\\.4")
expect_match(info.laser "${LAST_OUT}" "RESL")
expect_match(info.laser "${LAST_OUT}" "laser table")
run(0 decompress.laser decompress "${WORK}/k_l.lex3dm" -o "${WORK}/k_l.bin" --reference "${KITTI}" --json)
expect_match(decompress.laser "${LAST_OUT}" "\"hausdorff_m\":(0\\.01[0-9]*|0\\.00[0-9]*|0\\.020*[,}]|[0-9.]+e-)")
run(1 compress.bad_coding compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --max-error 0.02 --layer-coding octree)
run(1 compress.voxel_keep_all compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --max-error 0.02 --layer-coding voxel --keep-all-points)
run(1 compress.bad_error compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --max-error 0)
run(1 compress.bad_error_text compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --max-error lots)
run(1 compress.both compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --max-error 0.01 --target-bpp 4)
run(1 compress.words_off_no_layer compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --words off)
run(2 compress.target_unreachable compress "${NC}" -o "${WORK}/nc_bad.lex3dm" --target-bpp 0.01 --words off)
# One sequence file for several scans, expanded again by decompress.
run(0 compress.one_file compress "${NC}" "${NC}" -o "${WORK}/set.lex3dq" --one-file --max-error 0.05 --words off --json)
expect_match(compress.one_file "${LAST_OUT}" "\"one_file\":true")
run(0 info.sequence info "${WORK}/set.lex3dq")
expect_match(info.sequence "${LAST_OUT}" "scans +2")
run(0 decompress.sequence decompress "${WORK}/set.lex3dq" -o "${WORK}/set.ply")
if(NOT EXISTS "${WORK}/set_000.ply" OR NOT EXISTS "${WORK}/set_001.ply")
  message(SEND_ERROR "[decompress.sequence] the scans were not written")
endif()
# Scans of distinct stems keep their names (sequence 1.1) and decode to OUT_<stem>.
run(0 compress.one_file_named compress "${NC}" "${KITTI}" -o "${WORK}/named.lex3dq" --one-file --max-error 0.05 --words off)
run(0 decompress.sequence_named decompress "${WORK}/named.lex3dq" -o "${WORK}/named.ply")
expect_match(decompress.sequence_named "${LAST_OUT}" "named_kitti00_000000.ply: [0-9]+ points \\(scan 2 of 2\\)")
if(NOT EXISTS "${WORK}/named_newer_college_00.ply" OR NOT EXISTS "${WORK}/named_kitti00_000000.ply"
   OR EXISTS "${WORK}/named_000.ply")
  message(SEND_ERROR "[decompress.sequence_named] the scans were not written under their names")
endif()
run(1 decompress.sequence_octomap decompress "${WORK}/set.lex3dq" --octomap "${WORK}/set.bt")
if(EXISTS "${WORK}/nc_bad.lex3dm")
  message(SEND_ERROR "[compress] an output was written for a refused residual layer")
endif()

# Scans already in the world frame (a registered map's scans, as PLY, no sensor pose):
# --input-frame world with the poses centres the coding on each scan's sensor again, so the
# layer costs about what the scan costs in its own frame; without them, centred on the
# world origin 50 m away, it costs much more. The inliers are counted from that sensor too.
file(WRITE "${WORK}/world_pose.txt" "0.8775825619 -0.4794255386 0 50 0.4794255386 0.8775825619 0 20 0 0 1 2\n")
execute_process(COMMAND "${TRANSFORM}" "${KITTI}" "${WORK}/world.ply" "${WORK}/world_pose.txt" RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(SEND_ERROR "[world] the test helper could not write the world-frame scan (${rc})")
endif()
function(total_bytes name var)
  string(REGEX MATCH "\"total_bytes\":([0-9]+)" m "${LAST_OUT}")
  if(NOT m)
    message(SEND_ERROR "[${name}] no total_bytes in: ${LAST_OUT}")
  endif()
  set(${var} "${CMAKE_MATCH_1}" PARENT_SCOPE)
endfunction()
run(0 world.sensor compress "${KITTI}" -o "${WORK}/w_s.lex3dm" --max-error 0.014 --json)
total_bytes(world.sensor sensor_bytes)
run(0 world.posed compress "${WORK}/world.ply" --poses "${WORK}/world_pose.txt" --input-frame world
    -o "${WORK}/w_p.lex3dm" --max-error 0.014 --json)
total_bytes(world.posed posed_bytes)
run(0 world.origin compress "${WORK}/world.ply" -o "${WORK}/w_o.lex3dm" --max-error 0.014 --json)
total_bytes(world.origin origin_bytes)
math(EXPR posed_limit "${sensor_bytes} * 102 / 100")
math(EXPR origin_floor "${sensor_bytes} * 115 / 100")
if(posed_bytes GREATER posed_limit OR origin_bytes LESS origin_floor)
  message(SEND_ERROR "[world] bytes: sensor frame ${sensor_bytes}, world + poses ${posed_bytes} "
                     "(at most ${posed_limit}), world without ${origin_bytes} (at least ${origin_floor})")
endif()
run(0 world.words compress "${WORK}/world.ply" --poses "${WORK}/world_pose.txt" --input-frame world
    -o "${WORK}/w_w.lex3dm" --iterations 20)
run(0 world.inliers decompress "${WORK}/w_w.lex3dm" -o "${WORK}/w_w.ply" --reference "${WORK}/world.ply" --json)
string(REGEX MATCH "\"inliers\":0\\.([0-9][0-9])" m "${LAST_OUT}")
if(NOT m OR CMAKE_MATCH_1 LESS 50)
  message(SEND_ERROR "[world.inliers] under 50 % inliers from the model's sensor: ${LAST_OUT}")
endif()
run(1 world.no_poses compress "${WORK}/world.ply" --input-frame world -o "${WORK}/w_bad.lex3dm")
run(1 world.bad_frame compress "${WORK}/world.ply" --input-frame map -o "${WORK}/w_bad.lex3dm")
if(EXISTS "${WORK}/w_bad.lex3dm")
  message(SEND_ERROR "[world] an output was written for a refused command")
endif()

# With an alphabet given, scans are read, coded and staged one at a time: a bad scan in
# the middle of a set stops the command (exit 2, its name in the message) and no output is
# left, neither the scans before it nor temporary files (all or nothing).
run(2 stream.bad_middle compress "${NC}" "${WORK}/odd.bin" "${NC}" --format binxyz -o "${WORK}/st.lex3dm"
    --alphabet "${WORK}/nc.lex3da")
expect_match(stream.bad_middle "${LAST_ERR}" "odd.bin")
file(GLOB leftovers "${WORK}/st_*" "${WORK}/.lex3d-*")
if(leftovers)
  message(SEND_ERROR "[stream.bad_middle] left files behind: ${leftovers}")
endif()
# With two threads, scans are coded two at a time, one thread each: a bad third scan stops
# the command and nothing is written.
run(2 stream.bad_third compress "${NC}" "${NC}" "${WORK}/odd.bin" "${NC}" --format binxyz -o "${WORK}/s3.lex3dm"
    --alphabet "${WORK}/nc.lex3da" --threads 2)
file(GLOB leftovers "${WORK}/s3_*" "${WORK}/.lex3d-*")
if(leftovers)
  message(SEND_ERROR "[stream.bad_third] left files behind: ${leftovers}")
endif()
# Scans side by side give the files of one thread, scan for scan.
run(0 stream.side_by_side compress "${NC}" "${KITTI}" "${NC}" -o "${WORK}/sb2.lex3dm" --alphabet "${WORK}/nc.lex3da"
    --threads 2)
run(0 stream.one_thread compress "${NC}" "${KITTI}" "${NC}" -o "${WORK}/sb1.lex3dm" --alphabet "${WORK}/nc.lex3da"
    --threads 1)
foreach(k 000 001 002)
  file(SHA256 "${WORK}/sb2_${k}.lex3dm" h2)
  file(SHA256 "${WORK}/sb1_${k}.lex3dm" h1)
  if(NOT h1 STREQUAL h2)
    message(SEND_ERROR "[stream.side_by_side] scan ${k} differs between one and two threads")
  endif()
endforeach()
# The same scan twice gives the same file twice (one scan's state never leaks into the next).
run(0 stream.twice compress "${NC}" "${NC}" -o "${WORK}/tw.lex3dm" --alphabet "${WORK}/nc.lex3da" --max-error 0.02 --words auto)
file(SHA256 "${WORK}/tw_000.lex3dm" h0)
file(SHA256 "${WORK}/tw_001.lex3dm" h1)
if(NOT h0 STREQUAL h1)
  message(SEND_ERROR "[stream.twice] the same scan coded twice gave two different files")
endif()
# --learn-scans K: the alphabet is learnt on K evenly spaced scans, the others coded with it.
run(0 learn_scans compress "${NC}" "${NC}" "${NC}" --learn-scans 1 --iterations 20 -o "${WORK}/ls.lex3dm"
    --save-alphabet "${WORK}/ls.lex3da" --json)
expect_match(learn_scans "${LAST_OUT}" "\"timings_ms\"")
file(SHA256 "${WORK}/ls_001.lex3dm" h1)
file(SHA256 "${WORK}/ls_002.lex3dm" h2)
if(NOT h1 STREQUAL h2)
  message(SEND_ERROR "[learn_scans] the two scans coded with the learnt alphabet differ")
endif()
run(0 learn_scans.decode decompress "${WORK}/ls_002.lex3dm" --alphabet "${WORK}/ls.lex3da" -o "${WORK}/ls_002.ply")
run(1 learn_scans.negative compress "${NC}" --learn-scans -1 -o "${WORK}/ls_bad.lex3dm")

# LAS: compressed LAS refused (exit 2, one line, nothing written); a bad LAS header names the file.
file(WRITE "${WORK}/scan.laz" "LASF not really")
run(2 las.laz compress "${WORK}/scan.laz" -o "${WORK}/laz.lex3dm" --max-error 0.05)
expect_match(las.laz "${LAST_ERR}" "LAZ")
if(EXISTS "${WORK}/laz.lex3dm")
  message(SEND_ERROR "[las.laz] an output was written")
endif()
file(WRITE "${WORK}/short.las" "LASF")
run(2 las.short info "${WORK}/short.las")
expect_match(las.short "${LAST_ERR}" "short.las: truncated LAS header")
# --- raw lidar logs: a capture that is not one, an Ouster capture without metadata ---
file(WRITE "${WORK}/fake.pcap" "this is not a packet capture\n")
run(2 pcap.not_a_capture compress "${WORK}/fake.pcap" -o "${WORK}/fake.lex3dm" --max-error 0.02)
expect_match(pcap.not_a_capture "${LAST_ERR}" "fake.pcap: not a readable pcap capture")
run(2 pcap.info_not_a_capture info "${WORK}/fake.pcap")
run(2 pcap.convert_not_a_capture convert "${WORK}/fake.pcap" "${WORK}/fake.pcd")
if(EXISTS "${WORK}/fake.lex3dm" OR EXISTS "${WORK}/fake.pcd")
  message(SEND_ERROR "[pcap.not_a_capture] an output was written for a bad capture")
endif()
run(1 pcap.bad_model info "${WORK}/fake.pcap" --sensor-model hdl64)

# --- outputs never clash with inputs or with each other (compared by file identity) ---
# file_unchanged(name path sha): the file still has the hash it had before the command.
function(file_unchanged name path sha)
  file(SHA256 "${path}" now)
  if(NOT now STREQUAL sha)
    message(SEND_ERROR "[${name}] ${path} was modified")
  endif()
endfunction()
function(no_file name path)
  if(EXISTS "${path}")
    message(SEND_ERROR "[${name}] ${path} was written")
  endif()
endfunction()
set(H "${WORK}/hard")
file(MAKE_DIRECTORY "${H}")
file(WRITE "${H}/p.txt" "1 0 0 0 0 1 0 0 0 0 1 0\n")
file(SHA256 "${H}/p.txt" poses_sha)
run(1 clash.poses compress "${KITTI}" --poses "${H}/p.txt" -o "${H}/p.txt" --max-error 0.02)
expect_match(clash.poses "${LAST_ERR}" "--poses")
file_unchanged(clash.poses "${H}/p.txt" "${poses_sha}")
# the same file under another spelling
run(1 clash.poses_dot learn "${NC}" --poses "${H}/p.txt" -o "${H}/./p.txt" --iterations 5)
file_unchanged(clash.poses_dot "${H}/p.txt" "${poses_sha}")
run(1 clash.poses_reconstruct reconstruct "${NC}" --poses "${H}/p.txt" -o "${H}/../hard/p.txt")
file_unchanged(clash.poses_reconstruct "${H}/p.txt" "${poses_sha}")
run(1 clash.poses_place place build "${H}/p.txt" "${NC}" --poses "${H}/p.txt")
file_unchanged(clash.poses_place "${H}/p.txt" "${poses_sha}")
# a hard link and a symbolic link to an input
file(COPY "${NC}" DESTINATION "${H}")
set(NCH "${H}/newer_college_00.bin")
file(SHA256 "${NCH}" nc_sha)
file(CREATE_LINK "${NCH}" "${H}/hard_link.bin")
file(CREATE_LINK "${NCH}" "${H}/sym_link.lex3dm" SYMBOLIC)
run(1 clash.hard_link convert "${NCH}" "${H}/hard_link.bin")
file_unchanged(clash.hard_link "${NCH}" "${nc_sha}")
run(1 clash.symlink compress "${NCH}" -o "${H}/sym_link.lex3dm" --max-error 0.05)
file_unchanged(clash.symlink "${NCH}" "${nc_sha}")
# the alphabet a database is built with
file(SHA256 "${WORK}/nc.lex3da" alpha_sha)
run(1 clash.place_alphabet place build "${WORK}/nc.lex3da" "${NC}" --alphabet "${WORK}/nc.lex3da")
file_unchanged(clash.place_alphabet "${WORK}/nc.lex3da" "${alpha_sha}")
# two outputs of one command
run(1 clash.model_alphabet compress "${NC}" -o "${H}/x.lex3dm" --save-alphabet "${H}/./x.lex3dm" --iterations 5)
no_file(clash.model_alphabet "${H}/x.lex3dm")
run(1 clash.cloud_octomap decompress "${WORK}/nc.lex3dm" -o "${H}/out.bin" --octomap "${H}/out.bin")
no_file(clash.cloud_octomap "${H}/out.bin")

# --- a failed command leaves no output at all ---
file(WRITE "${H}/a_file" "x")
run(3 partial.save_alphabet compress "${NC}" -o "${H}/m.lex3dm" --save-alphabet "${H}/a_file/alpha.lex3da" --iterations 5)
no_file(partial.save_alphabet "${H}/m.lex3dm")
# a database path that is a directory is refused before any work
run(3 partial.db_directory place build "${H}" "${NC}" --alphabet "${WORK}/nc.lex3da")
expect_match(partial.db_directory "${LAST_ERR}" "directory")
# a sequence whose second scan is corrupt: no scan is written
execute_process(COMMAND /usr/bin/python3 -c "import sys; d=bytearray(open(sys.argv[1],'rb').read()); d[-30]^=0xFF; open(sys.argv[2],'wb').write(d)"
                "${WORK}/set.lex3dq" "${H}/bad_seq.lex3dq")
run(2 partial.sequence decompress "${H}/bad_seq.lex3dq" -o "${H}/bs.ply")
no_file(partial.sequence "${H}/bs_000.ply")
file(GLOB leftovers "${H}/.lex3d-*" "${H}/bs_*")
if(leftovers)
  message(SEND_ERROR "[partial] left files behind: ${leftovers}")
endif()

# --- inputs that are not what they claim ---
run(2 kind.missing_alphabet compress "${NC}" -o "${H}/ma.lex3dm" --alphabet "${H}/no_such.lex3da")
expect_match(kind.missing_alphabet "${LAST_ERR}" "no_such.lex3da")
run(2 kind.scan_as_alphabet decompress "${WORK}/nc.lex3dm" --alphabet "${NC}" -o "${H}/sa.ply")
expect_match(kind.scan_as_alphabet "${LAST_ERR}" "--alphabet")
no_file(kind.scan_as_alphabet "${H}/sa.ply")
run(1 kind.model_as_ply compress "${NC}" -o "${H}/out.ply" --max-error 0.05)
no_file(kind.model_as_ply "${H}/out.ply")
run(1 kind.cloud_as_model decompress "${WORK}/nc.lex3dm" -o "${H}/out.lex3dm")
file(WRITE "${H}/poses.txt" "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n1 0 0 2 0 1 0 0 0 0 1 0\n")
run(2 kind.poses_as_cloud info "${H}/poses.txt")
expect_match(kind.poses_as_cloud "${LAST_ERR}" "pose list")
# a KITTI file (16 bytes a point) read as binxyz (12) is refused
run(2 kind.kitti_as_binxyz info --format binxyz "${KITTI}")
expect_match(kind.kitti_as_binxyz "${LAST_ERR}" "kitti")

# --- non-regular inputs are refused at once (no blocking on a FIFO, no endless read) ---
execute_process(COMMAND mkfifo "${H}/fifo.bin" RESULT_VARIABLE fifo_rc)
if(fifo_rc EQUAL 0)
  run(2 nonregular.fifo info "${H}/fifo.bin")
  expect_match(nonregular.fifo "${LAST_ERR}" "not a regular file")
endif()
run(2 nonregular.device info /dev/zero)
run(2 nonregular.device_compress compress /dev/zero -o "${H}/zero.lex3dm" --max-error 0.05)
no_file(nonregular.device_compress "${H}/zero.lex3dm")

# --- one point at 1e30 is dropped and counted, not a usage error ---
execute_process(COMMAND /usr/bin/python3 -c "import struct,sys; d=open(sys.argv[1],'rb').read(); open(sys.argv[2],'wb').write(d+struct.pack('<4f',1e30,1e30,1e30,0))"
                "${KITTI}" "${H}/outlier.bin")
run(0 outlier.compress compress "${H}/outlier.bin" -o "${H}/outlier.lex3dm" --max-error 0.02)
expect_match(outlier.compress "${LAST_ERR}" "outlier.bin: 1 point farther than [0-9]+ m from the sensor dropped")
run(0 outlier.info info --json "${H}/outlier.bin")
expect_match(outlier.info "${LAST_OUT}" "\"far_dropped\":1")

# --- degenerate clouds get a bounded range image ---
# Seeded, so that every run reads the same bytes.
execute_process(COMMAND /usr/bin/python3 -c "import random,sys; open(sys.argv[1],'wb').write(random.Random(7).randbytes(102400))"
                "${H}/random.bin")
run(0 degenerate.random features --json "${H}/random.bin")
# at most max(16 pixels a point, 2^18) pixels
string(REGEX MATCH "\"points\":([0-9]+)" _ "${LAST_OUT}")
set(deg_points "${CMAKE_MATCH_1}")
string(REGEX MATCH "\"width\":([0-9]+),\"height\":([0-9]+)" _ "${LAST_OUT}")
if(deg_points STREQUAL "" OR CMAKE_MATCH_1 STREQUAL "")
  message(SEND_ERROR "[degenerate.random] no point count or image size in: ${LAST_OUT}")
else()
  math(EXPR deg_pixels "${CMAKE_MATCH_1} * ${CMAKE_MATCH_2}")
  math(EXPR deg_cap "16 * ${deg_points}")
  if(deg_cap LESS 262144)
    set(deg_cap 262144)
  endif()
  math(EXPR deg_cap "${deg_cap} + ${deg_cap} / 20")
  if(deg_pixels GREATER deg_cap)
    message(SEND_ERROR "[degenerate.random] range image of ${deg_pixels} pixels for ${deg_points} points")
  endif()
endif()

# --- place databases that pass the CRCs but not the field checks, or have empty entries ---
set(PATCH_DB "${CMAKE_CURRENT_LIST_DIR}/patch_place_db.py")
run(0 placedb.build8 place build "${H}/db8.lex3dp" "${NC}" "${KITTI}" --alphabet "${WORK}/nc.lex3da" --descriptor-bits 8)
execute_process(COMMAND /usr/bin/python3 "${PATCH_DB}" "${H}/db8.lex3dp" "${H}/db_az.lex3dp" az_tiny)
execute_process(COMMAND /usr/bin/python3 "${PATCH_DB}" "${H}/db8.lex3dp" "${H}/db_nofeat.lex3dp" nofeat)
# an azimuth resolution a 16-bit image width cannot span: refused at load
run(2 placedb.azimuth_resolution place query "${H}/db_az.lex3dp" "${NC}")
expect_match(placedb.azimuth_resolution "${LAST_ERR}" "db_az.lex3dp: place database: the coarse image's azimuth")
# an entry without features (8-bit descriptors): loads, and the query still ranks both scans
run(0 placedb.no_features place query "${H}/db_nofeat.lex3dp" "${NC}")
expect_match(placedb.no_features "${LAST_OUT}" "kitti00_000000 score")
