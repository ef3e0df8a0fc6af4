"""USB HID control boxes through hidapi: known profiles plus a report-descriptor parser, so an
unknown panel or gamepad still works."""
