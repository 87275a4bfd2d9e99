# Embeds OpenCL C sources into the binary as {name, source, hash} records.
#
#   softshell_embed_kernels(TARGET <lib> OUTPUT <file.cpp> SOURCES <a.cl> <b.h> ...)
#
# The generated file says "generated, do not edit" and is only rewritten when its
# content changes, so touching nothing rebuilds nothing. Sources are stored
# verbatim (as byte arrays, no escaping), so build-log line numbers match the
# files in kernels/.
set(_SOFTSHELL_EMBED_SCRIPT ${CMAKE_CURRENT_LIST_DIR}/embed_kernels_script.cmake)

function(softshell_embed_kernels)
  cmake_parse_arguments(ARG "" "TARGET;OUTPUT" "SOURCES" ${ARGN})
  set(_abs)
  foreach(src IN LISTS ARG_SOURCES)
    get_filename_component(a ${src} ABSOLUTE)
    list(APPEND _abs ${a})
  endforeach()
  string(REPLACE ";" "|" _joined "${_abs}")
  add_custom_command(
    OUTPUT ${ARG_OUTPUT}
    COMMAND ${CMAKE_COMMAND} -DOUTPUT=${ARG_OUTPUT} "-DSOURCES=${_joined}"
            -P ${_SOFTSHELL_EMBED_SCRIPT}
    DEPENDS ${_abs} ${_SOFTSHELL_EMBED_SCRIPT}
    COMMENT "Embedding OpenCL kernels"
    VERBATIM)
  target_sources(${ARG_TARGET} PRIVATE ${ARG_OUTPUT})
endfunction()
