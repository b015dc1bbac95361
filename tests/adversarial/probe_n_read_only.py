"""N. The file system under a running server turns read-only (ext4's errors=remount-ro after a disk error): every
write is UNAVAILABLE, as the proto promises, never INTERNAL; reads keep working. The database lives on a small
ext4 image mounted through a loop device; ext4's trigger_fs_error knob turns it read-only while the server holds
its files open (a plain `mount -o remount,ro` refuses while files are open for writing). Needs root, loop devices
and mkfs.ext4: skipped with the reason otherwise."""
import os
import shutil
import subprocess

import adv_harness as h

CLASS = "N"
TITLE = "the file system turns read-only under a running server"


def sh(*args):
    return subprocess.run(list(args), capture_output=True, text=True, timeout=60)


def mount_image(tmp):
    """Mounts a fresh 64 MB ext4 image at tmp/fs; returns (mount point, trigger file) or a reason to skip."""
    if os.geteuid() != 0:
        return None, "not root (mounting a loop device needs it)"
    if not shutil.which("mkfs.ext4"):
        return None, "mkfs.ext4 is not installed"
    image, mnt = os.path.join(tmp, "fs.img"), os.path.join(tmp, "fs")
    os.makedirs(mnt)
    with open(image, "wb") as f:
        f.truncate(64 << 20)
    p = sh("mkfs.ext4", "-q", "-F", image)
    if p.returncode != 0:
        return None, f"mkfs.ext4 failed: {p.stderr.strip()}"
    p = sh("mount", "-o", "loop,errors=remount-ro", image, mnt)
    if p.returncode != 0:
        return None, f"mount -o loop is not permitted here: {p.stderr.strip()}"
    dev = os.path.basename(sh("findmnt", "-n", "-o", "SOURCE", mnt).stdout.strip())
    trigger = f"/sys/fs/ext4/{dev}/trigger_fs_error"
    if not os.path.exists(trigger):
        sh("umount", mnt)
        return None, f"{trigger} is missing (a kernel without ext4's error trigger)"
    return (mnt, trigger), None


def writes_unavailable(s, trigger):
    pb, C = h.pb, h.C
    s.admin.CreateMap(pb.CreateMapRequest(name="m"), timeout=30)
    s.loop.Ingest(pb.IngestRequest(key=h.key("r", 1), scan=h.synthetic_scan(2000, seed=101)), timeout=30)
    with open(trigger, "w") as f:
        f.write("sglc adversarial probe N")
    writes = [("Ingest", lambda t: s.loop.Ingest(pb.IngestRequest(key=h.key("r", 2), scan=h.synthetic_scan(
                  2000, seed=102)), timeout=t)),
              ("CreateMap", lambda t: s.admin.CreateMap(pb.CreateMapRequest(name="m2"), timeout=t)),
              ("DeleteSession", lambda t: s.admin.DeleteSession(pb.DeleteSessionRequest(map="m", robot="r",
                                                                                        session="run"), timeout=t)),
              ("Backup", lambda t: s.admin.Backup(pb.BackupRequest(path="after.db"), timeout=t))]
    problems = []
    for name, call in writes:
        try:
            h.expect_error(s, call, C.UNAVAILABLE, any_words=("cannot be written", "read-only", "cannot be created"),
                           check_stored=False)
        except AssertionError as e:
            problems.append(f"{name}: {e}")
    stats = s.admin.GetStats(h.pb.GetStatsRequest(map="m"), timeout=30)
    if stats.scans != 1:
        problems.append(f"expected the one scan stored before to be readable, GetStats says {stats.scans}")
    assert not problems, "; ".join(problems)


def run(tmp):
    name = "N.read_only_file_system_writes_unavailable_reads_work"
    mounted, why = mount_image(tmp)
    if not mounted:
        h.skip(name, why)
        return
    mnt, trigger = mounted
    try:
        s = h.Server(os.path.join(mnt, "map.db"))
        try:
            h.probe(name, writes_unavailable, s, trigger)
        finally:
            s.stop()
    finally:
        p = sh("umount", mnt)
        if p.returncode != 0:
            sh("umount", "-l", mnt)
