//! Outputs to the farm: register map, Modbus TCP/RTU server and client, serial line, feeding rule.
