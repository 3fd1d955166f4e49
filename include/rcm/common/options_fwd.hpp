#pragma once
// What a header that declares an options struct needs to declare its field
// table (rcm/common/options.hpp) without including it:
//
//   const OptionTable<JointEstimatorOptions>& get_option_table(OptionTag<JointEstimatorOptions>);
//
// and, next to an enum that options hold, the words that name its values:
//
//   const OptionChoices<StaticStep>& get_option_choices(OptionTag<StaticStep>);

#include <string>
#include <utility>
#include <vector>

namespace rcm {

template <class T>
struct OptionTag {};

template <class T>
class OptionTable;

// The words of an enum's values, in the order help text lists them.
template <class E>
using OptionChoices = std::vector<std::pair<std::string, E>>;

}  // namespace rcm
