// Numbers as text for people and for files that are read back: the shortest decimal that
// parses back to the same double (0.2 prints as "0.2", not "0.20000000000000001").
#pragma once

#include <string>

namespace fl {

// Shortest round-trip text of `v` ("0.2", "1e-06", "3.0"); ".inf", "-.inf" and ".nan" for the
// non-finite values (the YAML spellings, which LoadYaml* read back). An integral value keeps a
// ".0" so that it still reads as a number with a fraction.
std::string FormatDouble(double v);
// The same for a float: the shortest text that reads back as the same float ("0.1").
std::string FormatFloat(float v);

}  // namespace fl
