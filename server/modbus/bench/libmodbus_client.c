/*
 * Benchmark peer: a C client on libmodbus, one connection.
 *
 * Sequential reads of 125 holding registers (function 03) from address 0,
 * one request in flight, for a bounded time and count; every reply is
 * checked. Built and run by
 * `cargo run --release -p gridscada-modbus --example bench` against the same
 * in-process server as gridscada's poller:
 *
 *   cc -O2 -o libmodbus_client libmodbus_client.c $(pkg-config --cflags --libs libmodbus)
 *
 * Usage: libmodbus_client HOST PORT UNIT SECONDS [MAX_REQUESTS]
 * Prints one JSON line: client, requests, seconds, requests_per_s, registers_per_s.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include <modbus.h>

#define REGISTERS 125
#define WARM_UP 50

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

int main(int argc, char **argv)
{
    if (argc != 5 && argc != 6) {
        fprintf(stderr, "usage: %s HOST PORT UNIT SECONDS [MAX_REQUESTS]\n", argv[0]);
        return 2;
    }
    const char *host = argv[1];
    int port = atoi(argv[2]);
    int unit = atoi(argv[3]);
    double seconds = atof(argv[4]);
    long max_requests = argc == 6 ? atol(argv[5]) : 10000000L;
    if (port <= 0 || port > 65535 || unit < 0 || unit > 255 || seconds <= 0) {
        fprintf(stderr, "libmodbus_client: bad arguments\n");
        return 2;
    }

    modbus_t *ctx = modbus_new_tcp(host, port);
    if (ctx == NULL) {
        fprintf(stderr, "libmodbus_client: modbus_new_tcp: %s\n", modbus_strerror(errno));
        return 1;
    }
    modbus_set_slave(ctx, unit);
    modbus_set_response_timeout(ctx, 2, 0);
    if (modbus_connect(ctx) == -1) {
        fprintf(stderr, "libmodbus_client: connect to %s:%d: %s\n", host, port, modbus_strerror(errno));
        modbus_free(ctx);
        return 1;
    }

    uint16_t regs[REGISTERS];
    for (int i = 0; i < WARM_UP; i++) {
        if (modbus_read_registers(ctx, 0, REGISTERS, regs) != REGISTERS) {
            fprintf(stderr, "libmodbus_client: read: %s\n", modbus_strerror(errno));
            modbus_close(ctx);
            modbus_free(ctx);
            return 1;
        }
    }
    long n = 0;
    double t0 = now();
    double deadline = t0 + seconds;
    while (n < max_requests && now() < deadline) {
        if (modbus_read_registers(ctx, 0, REGISTERS, regs) != REGISTERS) {
            fprintf(stderr, "libmodbus_client: read: %s\n", modbus_strerror(errno));
            modbus_close(ctx);
            modbus_free(ctx);
            return 1;
        }
        n++;
    }
    double secs = now() - t0;
    modbus_close(ctx);
    modbus_free(ctx);

    printf("{\"client\": \"libmodbus %s (C)\", \"requests\": %ld, \"seconds\": %.6f, "
           "\"requests_per_s\": %.3f, \"registers_per_s\": %.3f}\n",
           LIBMODBUS_VERSION_STRING, n, secs, n / secs, (double)n * REGISTERS / secs);
    return 0;
}
