/* JSON in and out for compiled_json.py, called through ctypes (the GIL released).
 *
 * Writing: verify's JSON rows in one pass. Row r is literals piece 0, field 0, piece 1, ...,
 * field F - 1, piece F, rows joined by a separator. A field is a column of numbers written
 * as Python's json module writes their .tolist() (floats in repr's layout from Ryu's
 * shortest round-trip digits, vendored in ryu/; non-finite floats as null; a row of several
 * as "[a, b]"), or of given texts.
 *
 * Reading: a poses file in its plain form, straight into arrays (read_poses, at the end). */

#include <math.h>
#include <stdlib.h>

#include "ryu/d2s.c"
#include "pow10_128.h"  /* POW10_MIN, POW10_MAX, POW10_128: written by the build */

enum { FLOAT = 0, INT = 1, BOOL = 2, TEXT = 3 };  /* compiled_json.py's kinds */

/* The decimal digits of m < 10^17 (Ryu's output), ending just before end: two at a time,
 * in 32-bit arithmetic below 10^8 (as Ryu's to_chars). */
static inline void write_digits(uint64_t m, char* end) {
  if ((m >> 32) != 0) {
    const uint64_t q = div1e8(m);
    uint32_t low = ((uint32_t) m) - 100000000 * ((uint32_t) q);
    m = q;
    for (int k = 0; k < 4; ++k) {
      end -= 2;
      memcpy(end, DIGIT_TABLE + 2 * (low % 100), 2);
      low /= 100;
    }
  }
  uint32_t m32 = (uint32_t) m;
  while (m32 >= 100) {
    end -= 2;
    memcpy(end, DIGIT_TABLE + 2 * (m32 % 100), 2);
    m32 /= 100;
  }
  if (m32 >= 10) {
    end -= 2;
    memcpy(end, DIGIT_TABLE + 2 * m32, 2);
  } else {
    *--end = (char) ('0' + m32);
  }
}

/* Python's repr of the double with bits `bits` ("null" if not finite) at r: at most 24
 * bytes, though up to 40 are written (what follows is overwritten). Its length. */
static int py_repr(const uint64_t bits, char* const r) {
  const bool sign = (bits >> 63) != 0;
  const uint64_t mantissa = bits & ((1ull << DOUBLE_MANTISSA_BITS) - 1);
  const uint32_t exponent = (uint32_t) ((bits >> DOUBLE_MANTISSA_BITS) & 0x7ffu);
  if (exponent == 0x7ffu) {
    memcpy(r, "null", 4);
    return 4;
  }
  int i = 0;
  if (sign) {
    r[i++] = '-';
  }
  if (exponent == 0 && mantissa == 0) {
    memcpy(r + i, "0.0", 3);
    return i + 3;
  }
  floating_decimal_64 v;
  if (d2d_small_int(mantissa, exponent, &v)) {  /* an integer below 2^53: its zeros dropped */
    while (v.mantissa % 10 == 0) {
      v.mantissa /= 10;
      ++v.exponent;
    }
  } else {
    v = d2d(mantissa, exponent);
  }
  /* the digits in a scratch with room for copies of fixed size (a few moves each, where
   * one of n bytes would call memcpy) */
  char digits[48];
  const int n = (int) decimalLength17(v.mantissa);
  write_digits(v.mantissa, digits + n);
  const int decpt = v.exponent + n;  /* the value is 0.DIGITS x 10^decpt */
  if (decpt > -4 && decpt <= 16) {   /* positional, as repr: from 1e-4 to below 1e16 */
    if (decpt <= 0) {
      memcpy(r + i, "0.000", 5);
      i += 2 - decpt;
      memcpy(r + i, digits, 17);
      return i + n;
    }
    if (decpt >= n) {
      memcpy(r + i, digits, 17);
      i += n;
      for (int k = n; k < decpt; ++k) r[i++] = '0';
      memcpy(r + i, ".0", 2);
      return i + 2;
    }
    memcpy(r + i, digits, 16);
    r[i + decpt] = '.';
    memcpy(r + i + decpt + 1, digits + decpt, 16);
    return i + n + 1;
  }
  r[i++] = digits[0];  /* d[.ddd]e+XX: a sign and at least two exponent digits, as repr */
  if (n > 1) {
    r[i++] = '.';
    memcpy(r + i, digits + 1, 16);
    i += n - 1;
  }
  int e = decpt - 1;
  r[i++] = 'e';
  r[i++] = e < 0 ? '-' : '+';
  if (e < 0) e = -e;
  if (e >= 100) {
    r[i++] = (char) ('0' + e / 100);
    e %= 100;
  }
  r[i++] = (char) ('0' + e / 10);
  r[i++] = (char) ('0' + e % 10);
  return i;
}

/* The decimal text of an int64 at r (at most 20 bytes); its length. */
static int int_text(const int64_t value, char* const r) {
  int i = 0;
  uint64_t m = (uint64_t) value;
  if (value < 0) {
    r[i++] = '-';
    m = 0 - m;
  }
  char digits[20];  /* up to 20 digits: write_digits takes at most 17 */
  int n = 0;
  do {
    digits[19 - n++] = (char) ('0' + m % 10);
    m /= 10;
  } while (m != 0);
  memcpy(r + i, digits + 20 - n, n);
  return i + n;
}

/* One entry k of a numeric column (data: float64, int64 or uint8 values) at r; its length. */
static inline int64_t number_text(const int32_t kind, const void* const data, const int64_t k,
                                  char* const r) {
  if (kind == FLOAT) {
    uint64_t bits;
    memcpy(&bits, (const char*) data + 8 * k, sizeof bits);
    return py_repr(bits, r);
  }
  if (kind == INT) {
    return int_text(((const int64_t*) data)[k], r);
  }
  if (((const uint8_t*) data)[k]) {
    memcpy(r, "true", 4);
    return 4;
  }
  memcpy(r, "false", 5);
  return 5;
}

/* n rows of F fields into out (room as compiled_json.py allows: 48 bytes more than the text);
 * field k: kind[k], width[k] (-1: one entry a row; w >= 0: a list of w), data[k] (the column's
 * values, row after row; TEXT: the texts' bytes) and, for TEXT, offsets[k] (n + 1 int64:
 * row r's text is bytes offsets[r] to offsets[r + 1]); literals with bounds (F + 2: piece k
 * is bytes bounds[k] to bounds[k + 1]). The text's length. */
int64_t json_rows(const int64_t n, const int32_t F, const int32_t* const kind,
                  const int64_t* const width, const void* const* const data,
                  const int64_t* const* const offsets, const char* const literals,
                  const int64_t* const bounds, const char* const separator,
                  const int64_t separator_size, char* const out) {
  int64_t o = 0;
  for (int64_t r = 0; r < n; ++r) {
    if (r > 0) {
      memcpy(out + o, separator, separator_size);
      o += separator_size;
    }
    for (int32_t k = 0; k <= F; ++k) {
      const int64_t size = bounds[k + 1] - bounds[k];
      memcpy(out + o, literals + bounds[k], size);
      o += size;
      if (k == F) break;
      if (kind[k] == TEXT) {
        const int64_t a = offsets[k][r], b = offsets[k][r + 1];
        memcpy(out + o, (const char*) data[k] + a, b - a);
        o += b - a;
      } else if (width[k] < 0) {
        o += number_text(kind[k], data[k], r, out + o);
      } else {
        out[o++] = '[';
        for (int64_t j = 0; j < width[k]; ++j) {
          if (j > 0) {
            out[o++] = ',';
            out[o++] = ' ';
          }
          o += number_text(kind[k], data[k], r * width[k] + j, out + o);
        }
        out[o++] = ']';
      }
    }
  }
  return o;
}

/* ----- reading: a poses file ----------------------------------------------------------- */

/* The document of a poses file in its plain form, read into arrays: a list of poses, or
 * {"poses": [...]}, each pose {"position": [x, y, z], "quaternion": [x, y, z, w]} or
 * {"position": [...], "tau": [phi, theta, sigma]} (its two keys in either order), JSON
 * numbers only, JSON whitespace anywhere allowed. Anything else (an empty list, another
 * key, a key twice, escapes, null, true, a string, a number JSON does not allow) is not
 * read: -1, and parsing/poses.py's json module parse says what is wrong. */

typedef struct {
  const char* s;
  const char* end;
} cursor;

static inline void skip_ws(cursor* c) {
  while (c->s < c->end && (*c->s == ' ' || *c->s == '\n' || *c->s == '\r' || *c->s == '\t')) {
    ++c->s;
  }
}

static inline bool take(cursor* c, const char ch) {
  skip_ws(c);
  if (c->s < c->end && *c->s == ch) {
    ++c->s;
    return true;
  }
  return false;
}

static inline bool is_digit(const char ch) {
  return ch >= '0' && ch <= '9';
}

/* Exact powers of ten as doubles (10^22 is the largest). */
static const double POW10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                 1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* w x 10^q (w > 0, at most 19 digits, exact) correctly rounded into *out by Eisel and
 * Lemire's method (Lemire, "Number parsing at a gigabyte per second", 2021): w, its top
 * bit at bit 63, times the truncated 128-bit mantissa of 10^q (POW10_128, written by the
 * build: compiled_json.py's pow10_table) gives the double's 53 bits and the bit below
 * them unless the product's low bits are so near a carry, or the bits below so near a
 * tie, that the truncation could decide: then false, as for a result that is subnormal,
 * zero or infinite (the caller then asks strtod). The binary exponent of 10^q is
 * floor(q log2 10) = (217706 q) >> 16 over the table's range (an arithmetic shift: GCC's
 * and Clang's >> of a negative number). */
static bool eisel_lemire(uint64_t w, const int64_t q, const bool negative, double* const out) {
  if (q < POW10_MIN || q > POW10_MAX || w == 0) return false;
  const int zeros = __builtin_clzll(w);
  w <<= zeros;
  const uint64_t* const t = POW10_128[q - POW10_MIN];  /* {high word, low word} */
  unsigned __int128 x = (unsigned __int128) w * t[0];
  uint64_t high = (uint64_t) (x >> 64), low = (uint64_t) x;
  if ((high & 0x1FF) == 0x1FF && low + w < low) {  /* the truncated part may carry into high */
    const unsigned __int128 y = (unsigned __int128) w * t[1];
    const uint64_t y_high = (uint64_t) (y >> 64), y_low = (uint64_t) y;
    const uint64_t sum = low + y_high;
    const uint64_t carried = high + (sum < low);
    if ((carried & 0x1FF) == 0x1FF && sum == UINT64_MAX && y_low + w < y_low) return false;
    high = carried;
    low = sum;
  }
  const uint64_t top = high >> 63;  /* the product's leading bit: 127 or 126 */
  uint64_t mantissa = high >> (top + 9);  /* 54 bits: the double's 53 and the one below */
  int64_t exponent = ((217706 * q) >> 16) + 64 + 1023 - zeros - (int64_t) (1 ^ top);
  if (low == 0 && (high & 0x1FF) == 0 && (mantissa & 3) == 1) return false;  /* a tie, maybe */
  mantissa += mantissa & 1;  /* round half up on the 54th bit (ties excluded above) */
  mantissa >>= 1;
  if (mantissa >> 53) {  /* rounded up to the next power of two */
    mantissa >>= 1;
    ++exponent;
  }
  if (exponent <= 0 || exponent >= 0x7FF) return false;
  const uint64_t bits = ((uint64_t) negative << 63) | ((uint64_t) exponent << 52)
                        | (mantissa & ((1ull << 52) - 1));
  memcpy(out, &bits, sizeof bits);
  return true;
}

/* A JSON number at c into *out, as Python's json module reads it: a float correctly
 * rounded (Clinger's fast path where the digits w <= 2^53 and the exponent q is within
 * 10^+-22, both exact doubles so one rounding is the only one; else Eisel-Lemire's for up
 * to 19 digits; else, and where that cannot decide, strtod, which rounds correctly in the
 * C locale, any other caught by the text not taken whole), an integer as float(int) (so
 * "-0" is 0.0); not finite: false. */
static bool take_number(cursor* c, double* const out) {
  skip_ws(c);
  const char* p = c->s;
  const char* const start = p;
  bool integer = true, negative = false;
  uint64_t w = 0;         /* the significant digits, while they fit */
  int digits = 0;         /* how many of them (leading zeros not counted) */
  int64_t q = 0;          /* the decimal exponent of w */
  if (p < c->end && *p == '-') {
    negative = true;
    ++p;
  }
  if (p >= c->end) return false;
  if (*p == '0') {
    ++p;
  } else if (*p >= '1' && *p <= '9') {
    while (p < c->end && is_digit(*p)) {
      if (digits < 19) w = 10 * w + (uint64_t) (*p - '0');
      else ++q;  /* beyond 19 digits: not the fast path (see below) */
      ++digits;
      ++p;
    }
  } else {
    return false;
  }
  if (p < c->end && *p == '.') {
    integer = false;
    ++p;
    if (p >= c->end || !is_digit(*p)) return false;
    while (p < c->end && is_digit(*p)) {
      if (digits > 0 || *p != '0') {
        if (digits < 19) {
          w = 10 * w + (uint64_t) (*p - '0');
          --q;
        }
        ++digits;
      } else {
        --q;  /* a leading zero of the fraction */
      }
      ++p;
    }
  }
  if (p < c->end && (*p == 'e' || *p == 'E')) {
    integer = false;
    ++p;
    bool minus = false;
    if (p < c->end && (*p == '+' || *p == '-')) minus = *p++ == '-';
    if (p >= c->end || !is_digit(*p)) return false;
    int64_t e = 0;
    while (p < c->end && is_digit(*p)) {
      if (e < 100000) e = 10 * e + (*p - '0');
      ++p;
    }
    q += minus ? -e : e;
  }
  if (p >= c->end) return false;  /* a number never ends a document: strtod needs a stop */
  double value;
  if (digits <= 19 && w <= (1ull << 53) && q >= -22 && q <= 22) {
    value = q < 0 ? (double) w / POW10[-q] : (double) w * POW10[q];
    if (negative) value = -value;
  } else if (!(digits <= 19 && eisel_lemire(w, q, negative, &value))) {
    char* stop;
    value = strtod(start, &stop);
    if (stop != p) return false;
  }
  if (!isfinite(value)) return false;
  *out = (integer && value == 0.0) ? 0.0 : value;
  c->s = p;
  return true;
}

/* Whether the exact text `word` (a key with its quotes) is at c, taken if so. */
static bool take_word(cursor* c, const char* const word) {
  skip_ws(c);
  const size_t n = strlen(word);
  if ((size_t) (c->end - c->s) < n || memcmp(c->s, word, n) != 0) return false;
  c->s += n;
  return true;
}

/* The key at c: 1 "position", 2 "quaternion", 3 "tau", 0 any other (or not a plain key). */
static int take_key(cursor* c) {
  static const char* const keys[] = {"\"position\"", "\"quaternion\"", "\"tau\""};
  for (int k = 0; k < 3; ++k) {
    if (take_word(c, keys[k])) return k + 1;
  }
  return 0;
}

/* "[a, b, ...]" of exactly n numbers at c into out. */
static bool take_numbers(cursor* c, const int n, double* const out) {
  if (!take(c, '[')) return false;
  for (int k = 0; k < n; ++k) {
    if ((k > 0 && !take(c, ',')) || !take_number(c, out + k)) return false;
  }
  return take(c, ']');
}

/* One pose at c into row (7 values: position, then the quaternion, or tau and a nan) and
 * *quaternion. */
static bool take_pose(cursor* c, double* const row, int8_t* const quaternion) {
  if (!take(c, '{')) return false;
  int seen = 0;  /* bit k: key k + 1 taken */
  for (int field = 0; field < 2; ++field) {
    if (field > 0 && !take(c, ',')) return false;
    const int key = take_key(c);
    if (key == 0 || (seen & (1 << (key - 1))) || !take(c, ':')) return false;
    seen |= 1 << (key - 1);
    if (key == 1) {
      if (!take_numbers(c, 3, row)) return false;
    } else {
      *quaternion = key == 2;
      if (!take_numbers(c, key == 2 ? 4 : 3, row + 3)) return false;
      if (key == 3) row[6] = NAN;  /* the rows are not filled before: untouched memory */
    }
  }
  return (seen & 1) && take(c, '}');  /* two distinct keys, position one of them */
}

/* The poses of the document text[0:size] into values (room for max_poses rows of 7) and
 * quaternion (max_poses: 1 where the pose gives a quaternion, 0 tau): their number, or -1
 * if the document is not in the plain form or holds more than max_poses poses. */
int64_t read_poses(const char* const text, const int64_t size, const int64_t max_poses,
                   double* const values, int8_t* const quaternion) {
  cursor c = {text, text + size};
  bool wrapped = false;
  if (take(&c, '{')) {
    if (!take_word(&c, "\"poses\"") || !take(&c, ':')) return -1;
    wrapped = true;
  }
  if (!take(&c, '[')) return -1;
  int64_t n = 0;
  do {
    if (n == max_poses || !take_pose(&c, values + 7 * n, quaternion + n)) return -1;
    ++n;
  } while (take(&c, ','));
  if (!take(&c, ']') || (wrapped && !take(&c, '}'))) return -1;
  skip_ws(&c);
  return c.s == c.end ? n : -1;
}
