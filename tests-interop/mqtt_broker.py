"""mosquitto (Debian's MQTT broker) on a free loopback port for one test: anonymous, no
persistence, its log in its own temporary directory. Used by bridge_interop.py and
gcs_mavproxy.py --via-broker."""

import os
import shutil
import socket
import subprocess
import tempfile
import time

# How long mosquitto may take to listen: a moment on an idle machine, seconds on a busy one (a
# deadline bounds a broken run only).
LISTEN_WITHIN = 30


def _free_tcp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    """mosquitto listening on 127.0.0.1:port; RuntimeError when it is missing or does not
    listen within LISTEN_WITHIN s (a missing broker is a failure, never a skip)."""

    def __init__(self, port=None, extra="", tls=None):
        """`tls`: a Certs; the listener then speaks TLS only and asks every client for a
        certificate signed by the same CA."""
        exe = shutil.which("mosquitto") or ("/usr/sbin/mosquitto" if os.path.exists("/usr/sbin/mosquitto") else None)
        if exe is None:
            raise RuntimeError("mosquitto is not installed (Debian package mosquitto; scripts/setup-system.sh installs it)")
        self.dir = tempfile.mkdtemp(prefix="mosquitto-")
        self.port = port or _free_tcp_port()
        conf = os.path.join(self.dir, "mosquitto.conf")
        with open(conf, "w") as f:
            # set_tcp_nodelay: a message goes when it comes (Nagle's delay would add up to 40 ms).
            f.write("listener %d 127.0.0.1\nallow_anonymous true\npersistence false\nset_tcp_nodelay true\n"
                    "max_connections -1\n%s" % (self.port, extra))
            if tls:
                f.write("cafile %s\ncertfile %s\nkeyfile %s\nrequire_certificate true\n" % (
                    tls.ca, tls.server_cert, tls.server_key))
        self.log = open(os.path.join(self.dir, "log"), "wb")
        self.proc = subprocess.Popen([exe, "-c", conf], stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + LISTEN_WITHIN
        self.tls = tls
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), 0.2).close()
                return
            except OSError:
                if self.proc.poll() is not None:
                    break
                time.sleep(0.05)
        self.stop()
        raise RuntimeError("mosquitto did not listen on port %d within %d s"
                           % (self.port, LISTEN_WITHIN))

    def url(self, fleet, vid, extra=""):
        """A bridge link string to this broker."""
        return "mqtt://127.0.0.1:%d?fleet=%s&vid=%s%s" % (self.port, fleet, vid, extra)

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.log.close()
        shutil.rmtree(self.dir, ignore_errors=True)


class Certs:
    """A throwaway CA, a server certificate for 127.0.0.1 (IP subjectAltName) and a client
    certificate, all made by the openssl command line in a temporary directory (keys PKCS#8
    PEM)."""

    def __init__(self):
        exe = shutil.which("openssl")
        if exe is None:
            raise RuntimeError("openssl is not installed (Debian package openssl)")
        self.dir = tempfile.mkdtemp(prefix="certs-")
        p = lambda name: os.path.join(self.dir, name)  # noqa: E731
        self.ca, self.ca_key = p("ca.pem"), p("ca.key")
        self.server_cert, self.server_key = p("server.pem"), p("server.key")
        self.client_cert, self.client_key = p("client.pem"), p("client.key")

        def run(*args):
            subprocess.run([exe, *args], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

        run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", self.ca_key, "-out", self.ca,
            "-days", "2", "-subj", "/CN=mavstack test CA")
        for cert, key, cn, ext in ((self.server_cert, self.server_key, "127.0.0.1", "subjectAltName=IP:127.0.0.1"),
                                   (self.client_cert, self.client_key, "truck-7", "extendedKeyUsage=clientAuth")):
            csr = cert + ".csr"
            run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", csr, "-subj", "/CN=%s" % cn)
            extfile = cert + ".ext"
            with open(extfile, "w") as f:
                f.write(ext + "\n")
            run("x509", "-req", "-in", csr, "-CA", self.ca, "-CAkey", self.ca_key, "-CAcreateserial",
                "-out", cert, "-days", "2", "-extfile", extfile)
        # mosquitto run as root reads them as the user it drops to (throwaway test keys).
        os.chmod(self.dir, 0o755)
        for name in os.listdir(self.dir):
            os.chmod(os.path.join(self.dir, name), 0o644)

    def close(self):
        shutil.rmtree(self.dir, ignore_errors=True)
