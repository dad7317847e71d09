// The one codec of the settings: get, set, check, defaults, pack and unpack walk the settings
// table (kSettingTable in protocol_gen.h, generated from protocol/eelbot.toml: type, count, place
// in struct Settings, range and default of each setting). A table read at run time rather than
// code per setting: 17 settings in ~1 KB of the AVR's flash. Values travel as float (SetSetting,
// Setting); a setting stored as an integer takes whole values only.
#pragma once
#include <stdint.h>

#include "protocol_gen.h"

namespace eelproto {

// RefuseReason value (0 when found): the value of element `index` of setting `key`.
uint8_t setting_get(const Settings& s, uint8_t key, uint8_t index, float& value);
// RefuseReason value (0 when set): element `index` of setting `key` becomes `value`, when it is
// finite, in the setting's range and (for an integer setting) whole; otherwise nothing changes.
// `changed` tells whether the stored value differs from before.
uint8_t setting_set(Settings& s, uint8_t key, uint8_t index, float value, bool& changed);
// Every setting at its documented default.
Settings settings_defaults();
// RefuseReason value of the first element out of range (or not finite), 0 when all are valid.
uint8_t settings_check(const Settings& s);
// The stored form: kSettingsBytes bytes, each element little-endian, in the table's order.
void settings_pack(const Settings& s, uint8_t* p);
void settings_unpack(Settings& s, const uint8_t* p);

}  // namespace eelproto
