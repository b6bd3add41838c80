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
# Alphabet reuse: a learned alphabet file, models that reference it.
run(0 compress.save compress "${NC}" -o "${WORK}/nc_ref.lex3dm" --save-alphabet "${WORK}/nc.lex3da" --iterations 30)
run(0 info.alphabet info --json "${WORK}/nc.lex3da")
expect_match(info.alphabet "${LAST_OUT}" "\"kind\":\"alphabet\"")
run(0 compress.reuse compress "${NC}" -o "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/nc.lex3da")
run(1 decompress.no_alphabet decompress "${WORK}/nc_reuse.lex3dm" -o "${WORK}/x.ply")
run(0 decompress.with_alphabet decompress "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/nc.lex3da" -o "${WORK}/nc_reuse.ply")
# A wrong alphabet is bad data; a corrupt model is bad data; no partial outputs.
run(0 learn.other learn "${SAMPLES}/room_scan1.pcd" -o "${WORK}/other.lex3da" --iterations 10)
run(2 decompress.wrong_alphabet decompress "${WORK}/nc_reuse.lex3dm" --alphabet "${WORK}/other.lex3da" -o "${WORK}/y.ply")
# Truncated and corrupt model files are covered byte by byte in test_codec; here a
# file that is not a model at all.
run(2 decompress.garbage decompress "${WORK}/garbage.alpha" -o "${WORK}/z.ply")
if(EXISTS "${WORK}/y.ply" OR EXISTS "${WORK}/z.ply" OR EXISTS "${WORK}/x.ply")
  message(SEND_ERROR "[decompress] an output was written for bad input")
endif()
run(1 compress.overwrite compress "${NC}" -o "${NC}")
