# Training flights of propid_sitl's profile-guided build (cmake -P; see
# CMakeLists.txt here): TRAINING = the instrumented executable, PGO_DIR = where
# its profile goes. The flights are fixed: the Crazyflie presets (plus, X) on
# the circle and the step, default and --paper sensors, the filter in the
# loop, and a short hexa and octo flight so that the general rotor-count code
# is not taken for cold. The Lissajous, which `make bench` times, is not one
# of them.
file(REMOVE_RECURSE "${PGO_DIR}/raw" "${PGO_DIR}/use")
set(flights
    "--vehicle crazyflie-plus --trajectory circle --duration 4 --seed 101"
    "--vehicle crazyflie-plus --trajectory step --duration 4 --seed 102 --paper"
    "--vehicle crazyflie-x --trajectory circle --duration 4 --seed 103 --paper"
    "--vehicle crazyflie-x --trajectory step --duration 4 --seed 104"
    "--vehicle hexa-x --trajectory circle --duration 1 --seed 105"
    "--vehicle octo-plus --trajectory circle --duration 1 --seed 106 --paper")
foreach(flight IN LISTS flights)
  separate_arguments(argv UNIX_COMMAND "${flight}")
  execute_process(COMMAND "${TRAINING}" --quiet ${argv} RESULT_VARIABLE rc OUTPUT_QUIET)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "propid_sitl training flight failed (${rc}): ${flight}")
  endif()
endforeach()
# The profile files are named after the instrumented objects; the optimised
# build's objects differ only in _gen -> _use.
file(GLOB profiles RELATIVE "${PGO_DIR}/raw" "${PGO_DIR}/raw/*.gcda")
if(NOT profiles)
  message(FATAL_ERROR "propid_sitl training wrote no profile under ${PGO_DIR}/raw")
endif()
file(MAKE_DIRECTORY "${PGO_DIR}/use")
foreach(name IN LISTS profiles)
  string(REPLACE "_gen" "_use" used "${name}")
  file(COPY_FILE "${PGO_DIR}/raw/${name}" "${PGO_DIR}/use/${used}")
endforeach()
file(TOUCH "${PGO_DIR}/profile.stamp")
