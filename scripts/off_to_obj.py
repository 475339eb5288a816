"""Converts an OFF mesh (CGAL's data format) to Wavefront OBJ, which vdb_tool reads. Usage: off_to_obj.py IN OUT"""
import sys

lines = [l for l in open(sys.argv[1]).read().split("\n") if l.strip() and not l.startswith("#")]
assert lines[0].strip() == "OFF", "not an OFF file"
vertices, faces = map(int, lines[1].split()[:2])
with open(sys.argv[2], "w") as out:
    for line in lines[2 : 2 + vertices]:
        out.write("v " + " ".join(line.split()[:3]) + "\n")
    for line in lines[2 + vertices : 2 + vertices + faces]:
        parts = line.split()
        out.write("f " + " ".join(str(int(i) + 1) for i in parts[1 : 1 + int(parts[0])]) + "\n")
