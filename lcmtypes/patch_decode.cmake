# Patches the C++ headers lcm-gen wrote in DIR (see include/fusionloc_lcm_guard.hpp for why):
#  - before every `this->X.resize(this->N);` of a decoder: refuse N that cannot fit in the
#    bytes left (fl_lcm_guard::CountFits), so nothing of a claimed size is allocated first;
#  - every string length check also refuses lengths below 1, and a string with a NUL inside
#    is refused (fl_lcm_guard::NoNul).
# Idempotent (a marker line); run after each lcm-gen.
file(GLOB_RECURSE _headers ${DIR}/*.hpp)
set(_marker "// fusionloc: decode bounds checked (lcmtypes/patch_decode.cmake)")
foreach(h ${_headers})
  file(READ ${h} _text)
  string(FIND "${_text}" "${_marker}" _done)
  if(NOT _done EQUAL -1)
    continue()
  endif()
  string(REPLACE "#include <lcm/lcm_coretypes.h>"
         "#include <lcm/lcm_coretypes.h>\n#include \"fusionloc_lcm_guard.hpp\"\n${_marker}"
         _text "${_text}")
  string(REGEX REPLACE
         "\n([ ]*)(this->[A-Za-z0-9_]+(\\[a[0-9]+\\])*)\\.resize\\((this->[A-Za-z0-9_]+)\\);"
         "\n\\1if (!fl_lcm_guard::CountFits<decltype(\\2)>(\\4, maxlen - pos)) return -1;\n\\1\\2.resize(\\4);"
         _text "${_text}")
  string(REGEX REPLACE "if\\((__[A-Za-z0-9_]+) > maxlen - pos\\) return -1;"
         "if(\\1 < 1 || \\1 > maxlen - pos) return -1;" _text "${_text}")
  string(REGEX REPLACE
         "\n([ ]*)(this->[A-Za-z0-9_]+(\\[a[0-9]+\\])*)\\.assign\\(\\(\\(const char\\*\\)buf\\) \\+ offset \\+ pos, (__[A-Za-z0-9_]+) - +1\\);"
         "\n\\1if (!fl_lcm_guard::NoNul(buf, offset + pos, \\4 - 1)) return -1;\n\\1\\2.assign(((const char*)buf) + offset + pos, \\4 - 1);"
         _text "${_text}")
  file(WRITE ${h} "${_text}")
endforeach()
