// `oclvox devices`: the OpenCL platforms and devices, with the "P:D" ids --device takes.
#include "commands.hpp"
#include "options.hpp"
#include "report.hpp"

namespace oclvox_cli {

Command add_devices_command(CLI::App& app) {
    CLI::App* command = app.add_subcommand("devices", "list the OpenCL platforms and devices");
    command->footer(kExitCodesText);
    auto reporting = std::make_shared<ReportingArgs>();
    add_reporting_options(*command, *reporting, false);
    return {command, [reporting] {
                const Clock::time_point start = Clock::now();
                check_reporting(*reporting, {}, {});
                RunRecord record;
                record.command = "devices";
                record.devices = oclvox::list_devices();
                if (record.devices.empty())
                    throw oclvox::DeviceError("OpenCL platforms exist but have no devices");
                record.seconds.total = seconds_since(start);
                report_run(record, *reporting, false);
                return 0;
            }};
}

}  // namespace oclvox_cli
