# Runs two count_step ELFs under QEMU (cmake -P; EMULATOR, WITH_BLOCK_MOVES,
# PORTABLE given with -D) and fails unless both exit 0, print the same variants
# and every variant's final_state_bits is the same in both.
foreach(_which WITH_BLOCK_MOVES PORTABLE)
  execute_process(COMMAND ${EMULATOR} "${${_which}}"
                  OUTPUT_VARIABLE _out_${_which} ERROR_VARIABLE _err_${_which}
                  RESULT_VARIABLE _rc_${_which} TIMEOUT 240)
  if(NOT _rc_${_which} EQUAL 0)
    message(FATAL_ERROR "${${_which}} exited ${_rc_${_which}}:\n${_out_${_which}}${_err_${_which}}")
  endif()
  # Semihosting output may arrive on either stream: read both.
  string(REGEX MATCHALL "[a-z_]+: [^\n]* final_state_bits [0-9]+"
         _lines_${_which} "${_out_${_which}}${_err_${_which}}")
  set(_bits_${_which} "")
  foreach(_line IN LISTS _lines_${_which})
    string(REGEX REPLACE "^([a-z_]+): .* final_state_bits ([0-9]+)$" "\\1=\\2" _pair "${_line}")
    list(APPEND _bits_${_which} "${_pair}")
  endforeach()
endforeach()
list(LENGTH _bits_PORTABLE _variants)
if(_variants LESS 2)
  message(FATAL_ERROR "expected the quad plus and X variants, read: '${_bits_PORTABLE}'\n${_out_PORTABLE}${_err_PORTABLE}")
endif()
if(NOT "${_bits_WITH_BLOCK_MOVES}" STREQUAL "${_bits_PORTABLE}")
  message(FATAL_ERROR "block moves: ${_bits_WITH_BLOCK_MOVES}\nportable C:  ${_bits_PORTABLE}")
endif()
message(STATUS "final states identical: ${_bits_PORTABLE}")
