"""PSNR (dB, over RGB) of one 8-bit PNG against another, with a PNG reader of its own (zlib and numpy only: the
bench venvs have no imaging library). Usage: python png_psnr.py REFERENCE.png IMAGE.png [DIFFERENCE.pgm]; the
optional third path gets the absolute difference, amplified 8 times, as a greyscale PGM."""
import struct
import sys
import zlib

import numpy as np


def read_png(path):
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    at, idat, header = 8, [], None
    while at < len(data):
        (length,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        at += 12 + length
    width, height, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in (0, 2, 4, 6) or interlace:
        raise ValueError(f"{path}: only 8-bit, non-interlaced PNGs are read here")
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[colour]
    raw = zlib.decompress(b"".join(idat))
    stride = width * channels
    out = np.zeros((height, stride), np.int32)
    previous = np.zeros(stride, np.int32)
    for y in range(height):
        kind = raw[y * (stride + 1)]
        row = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        if kind == 0:
            line = row
        elif kind == 2:
            line = (row + previous) & 255
        else:
            line = np.zeros(stride, np.int32)
            for x in range(stride):
                left = line[x - channels] if x >= channels else 0
                up = previous[x]
                corner = previous[x - channels] if x >= channels else 0
                if kind == 1:
                    predictor = left
                elif kind == 3:
                    predictor = (left + up) // 2
                else:
                    p = left + up - corner
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - corner)
                    predictor = left if pa <= pb and pa <= pc else (up if pb <= pc else corner)
                line[x] = (row[x] + predictor) & 255
        out[y] = line
        previous = line
    return out.reshape(height, width, channels)[..., :3].astype(np.uint8)


def psnr(image, reference):
    mse = np.mean((image.astype(np.float64) - reference.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0 ** 2 / mse))


if __name__ == "__main__":
    reference, image = read_png(sys.argv[1]), read_png(sys.argv[2])
    print(f"{psnr(image, reference):.2f}")
    if len(sys.argv) > 3:
        difference = np.abs(image.astype(np.int32) - reference.astype(np.int32)).max(axis=2)
        amplified = np.clip(difference * 8, 0, 255).astype(np.uint8)
        with open(sys.argv[3], "wb") as f:
            f.write(f"P5 {amplified.shape[1]} {amplified.shape[0]} 255\n".encode())
            f.write(amplified.tobytes())
