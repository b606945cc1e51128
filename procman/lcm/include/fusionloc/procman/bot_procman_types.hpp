// libbot2's bot_procman message types (lcmtypes/bot_procman/), in one include. GCC 12 warns
// of a maybe-uninitialized hash inside lcm-gen's decode() once a whole encode/decode round
// trip is inlined (a false positive: the hash is read before it is compared); the generated
// code is not ours, so the warning is off for it alone.
#pragma once

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include "bot_procman/command2_t.hpp"
#include "bot_procman/deputy_cmd2_t.hpp"
#include "bot_procman/discovery_t.hpp"
#include "bot_procman/info2_t.hpp"
#include "bot_procman/orders2_t.hpp"
#include "bot_procman/printf_t.hpp"
#include "bot_procman/sheriff_cmd2_t.hpp"
#pragma GCC diagnostic pop
