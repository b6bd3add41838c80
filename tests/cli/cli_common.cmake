# Shared by the CLI test scripts: run() and expect_match().

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

# The attribute `field` of a `compress --json` output `text` (its entry matching `what`
# right after the name, e.g. "\"representation\":\"as time float32"; empty for any) holds
# at most `most` bytes.
function(expect_field_bytes name text field what most)
  string(REGEX MATCH "\"name\":\"${field}\",${what}[^}]*\"bytes\":([0-9]+)" _ "${text}")
  if(NOT CMAKE_MATCH_1 OR CMAKE_MATCH_1 GREATER ${most})
    message(SEND_ERROR "[${name}] ${field} field of '${CMAKE_MATCH_1}' bytes, expected at most ${most}")
  endif()
endfunction()
