// What the health renderings (core/health/health_format.cpp) share between their files: the family
// header and the storage part (core/health/health_format_storage.cpp). Internal to the
// two renderings; everything else uses core/health/health_format.hpp.
#pragma once

#include <string>
#include <string_view>

#include "core/health/health.hpp"

namespace pandarcap::health_format {

// "# HELP pandarcap_NAME... HELP" and "# TYPE pandarcap_NAME... TYPE" lines.
void family(std::string& out, std::string_view name, std::string_view type, std::string_view help,
            std::string_view suffix = {});

// The storage gauges (docs/storage.md) and the upload backlog (docs/deploy.md): the .prom's
// samples, with `sensor` the rendered sensor label; the JSON line's "storage" object.
void storage_prometheus(std::string& out, std::string_view sensor, const StorageGauges& storage);
void storage_json(std::string& out, const StorageGauges& storage);

}  // namespace pandarcap::health_format
