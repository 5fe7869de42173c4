"""pymodbus client polling sim-device as fast as it can: the comparison for benches/client_rate.rs.

Usage: python3 pymodbus_rate.py HOST:PORT SECONDS
Runs the same cycles as the Rust bench (FC 23, then FC 16 + FC 3 on the default per-mille map)
with pymodbus's synchronous TCP client and prints cycles/s and transactions/s.
"""
import sys
import time

try:
    from pymodbus.client import ModbusTcpClient
except ImportError:
    sys.exit("pymodbus is not installed (python3 -m pip install 'pymodbus>=3.6,<4')")


def device_kw(fn):
    """pymodbus 3.x renamed the unit argument from `slave` to `device_id`."""
    import inspect
    params = inspect.signature(fn).parameters
    return "device_id" if "device_id" in params else "slave"


def main():
    host, port = sys.argv[1].rsplit(":", 1)
    secs = float(sys.argv[2])
    client = ModbusTcpClient(host, port=int(port), timeout=1)
    if not client.connect():
        sys.exit(f"cannot connect to {sys.argv[1]}")
    kw = device_kw(client.read_holding_registers)
    for fc23 in (True, False):
        n, faults, t0 = 0, 0, time.perf_counter()
        lat = []
        while time.perf_counter() - t0 < secs:
            raw = 200 + 10 * (n % 60)
            c0 = time.perf_counter()
            if fc23:
                r = client.readwrite_registers(read_address=1, read_count=1, write_address=0, values=[raw], **{kw: 1})
                faults += r.isError()
            else:
                w = client.write_registers(0, [raw], **{kw: 1})
                r = client.read_holding_registers(1, count=1, **{kw: 1})
                faults += w.isError() or r.isError()
            lat.append(time.perf_counter() - c0)
            n += 1
        el = time.perf_counter() - t0
        lat.sort()
        per = 1 if fc23 else 2
        name = "FC 23 (1 transaction/cycle)" if fc23 else "FC 16 + FC 3 (2 transactions/cycle)"
        print(f"pymodbus sync client, {name}: {n / el:.0f} cycles/s = {n * per / el:.0f} transactions/s; "
              f"cycle p50 {lat[len(lat) // 2] * 1e6:.0f} us, p99 {lat[int(len(lat) * 0.99)] * 1e6:.0f} us; {faults} faults")
    client.close()


if __name__ == "__main__":
    main()
