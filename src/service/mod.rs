//! Wiring of `fme run`: threads, queues, health and status, watchdog, shutdown.
