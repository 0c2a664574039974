#!/usr/bin/env python3
"""How long other requests wait while a large STL upload arrives.

usage: python3 bench/upload_stall.py BUILD_DIR [MB] [ROUNDS]

Starts `collidoscope serve` with one reactor thread (every connection on the
thread that reads the upload) on a free port and a fresh data folder, signs up,
and per round uploads an MB-megabyte binary STL while a second connection asks
for /api/v1/health every 2 ms. Prints per round the upload's time and the
longest health check; the server and its folder go when it ends.
"""
import http.client
import json
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time


def call(port, method, path, body=None, headers=None):
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    c.request(method, path, body=body, headers=headers or {})
    r = c.getresponse()
    data = r.read()
    c.close()
    return r.status, data


def health_waits(port, waits, stop):
    s = socket.create_connection(("127.0.0.1", port))
    ask = b"GET /api/v1/health HTTP/1.1\r\nHost: x\r\n\r\n"
    while not stop.is_set():
        t = time.perf_counter()
        s.sendall(ask)
        got = b""
        while True:
            end = got.find(b"\r\n\r\n")
            if end >= 0:
                length = int(re.search(rb"Content-Length: (\d+)", got[:end]).group(1))
                if len(got) >= end + 4 + length:
                    break
            got += s.recv(65536)
        waits.append(time.perf_counter() - t)
        time.sleep(0.002)
    s.close()


def main():
    build = sys.argv[1]
    mb = int(sys.argv[2]) if len(sys.argv) > 2 else 60
    rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 4
    data = tempfile.mkdtemp(prefix="upload_stall_")
    server = subprocess.Popen(
        [os.path.join(build, "app", "collidoscope"), "serve", "--port", "0", "--threads", "1",
         "--data", data, "--max-upload-mb", str(mb + 1)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        port = int(re.search(r"serving on http://127.0.0.1:(\d+)", server.stdout.readline()).group(1))
        who = json.dumps({"name": "uploader", "password": "correct horse battery"})
        js = {"Content-Type": "application/json"}
        call(port, "POST", "/api/v1/accounts", who, js)
        token = json.loads(call(port, "POST", "/api/v1/sessions", who, js)[1])["token"]
        auth = {"Authorization": "Bearer " + token}
        model = json.loads(call(port, "POST", "/api/v1/models",
                                json.dumps({"name": "big", "kind": "stl"}), {**js, **auth})[1])
        n = mb * 1024 * 1024 // 50
        triangle = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
        body = b"\0" * 80 + struct.pack("<I", n) + triangle * n
        print(f"# {mb} MB binary STL ({n} triangles), one reactor thread, health every 2 ms")
        print("| round | upload s | health checks | longest wait s |")
        print("|---:|---:|---:|---:|")
        for k in range(rounds):
            waits, stop = [], threading.Event()
            poller = threading.Thread(target=health_waits, args=(port, waits, stop))
            poller.start()
            time.sleep(0.2)
            t0 = time.perf_counter()
            status, answer = call(port, "PUT", f"/api/v1/models/{model['id']}/stl", body,
                                  {**auth, "Content-Type": "model/stl"})
            took = time.perf_counter() - t0
            time.sleep(0.2)
            stop.set()
            poller.join()
            if status != 200:
                sys.exit(f"upload answered {status}: {answer[:200]!r}")
            print(f"| {k + 1} | {took:.2f} | {len(waits)} | {max(waits):.3f} |")
    finally:
        server.terminate()
        server.wait()
        shutil.rmtree(data, ignore_errors=True)


if __name__ == "__main__":
    main()
