// Node targets' input: a sequence of records [channel byte][length u16 LE][payload], the
// payload an LCM-encoded message (with its fingerprint). Each is published on
// channels[byte % channels.size()] of a memq:// LCM with an increasing log time, handled
// (decode, then the node's handler), and the node polled. tests/fuzz/make_corpus.py writes
// seeds in this form.
#pragma once

#include <string>
#include <vector>

#include "fuzz_entry.hpp"
#include "fusionloc/common/lcm_interface.hpp"
#include "fusionloc/common/lcm_process.hpp"

namespace fl::fuzz {

void FeedMessages(Input* in, LcmInterface* lcm, const std::vector<std::string>& channels,
                  LcmNode* node);

}  // namespace fl::fuzz
