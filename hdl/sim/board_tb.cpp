// Verilator testbench of the camera board (hdl/rtl/stereo_board.v), run by hdl/sim.sh.
//
//   board_tb harris IMAGE.pgm THRESHOLD MAX_FEATURES [NAME]
//       Prints what `stereonav harris IMAGE --threshold T --max-features N` prints: the header
//       `x_q4,y_q4,r`, then the left camera's features. The image is given to both cameras;
//       the features are read back from the encoder's packet (its CRC checked), and the right
//       camera's must equal the left's.
//   board_tb packet OUT THRESHOLD MAX_FEATURES T0_US PERIOD_US FIRST_FRAME LEFT RIGHT [...]
//       Writes the board's byte stream for the stereo pairs to OUT, as
//       `stereonav fpga emulate OUT LEFT RIGHT ... --t0-us --period-us --first-frame` does.
//
// Environment: HDL_SIM_SEED=N (N > 0) makes the pixel stream and the link irregular, from a
// seeded generator: gaps between pixels, and a link that is not always ready; and every
// register and memory starts with random bits instead of zeros. The output must not change. Without it, one pixel per clock and a link that takes a byte per clock.
//
// Errors are reported like stereonav's: `stereonav: error: ...` on stderr, exit status 1 (2 for
// a malformed command line).
#include <cerrno>
#include <cinttypes>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "Vstereo_board.h"
#include "verilated.h"

namespace {

// ICD section 1.
constexpr long kMinSize = 16;
constexpr long kMaxSize = 4095;
constexpr long kMaxFeaturesLimit = 1023;
// ICD section 3.
constexpr size_t kHeaderBytes = 24;
constexpr size_t kFeatureBytes = 8;
constexpr size_t kCrcBytes = 4;
// A frame whose packet is not out this many clocks after its last pixel is a hang.
constexpr uint64_t kPacketTimeout = 1u << 22;

[[noreturn]] void fail(const std::string& message, int status = 1) {
    std::fprintf(stderr, "stereonav: error: %s\n", message.c_str());
    std::exit(status);
}

struct Image {
    long width = 0;
    long height = 0;
    std::vector<uint8_t> pixels;
};

// Reads a binary PGM (P5) with MAXVAL 1..=255, as stereonav's image reader does: a MAXVAL
// below 255 is scaled to 0..=255 by rounding v * (255 / MAXVAL) in f32; bytes after the image
// are ignored. Any other file is refused (hdl/sim.sh converts PNG and ASCII PGM first, with
// hdl/sim/to_pgm.py). `path` is the name the messages give.
Image read_pgm(const std::string& file_path, const std::string& path) {
    FILE* file = std::fopen(file_path.c_str(), "rb");
    if (file == nullptr) {
        fail("cannot open image " + path + ": " + std::strerror(errno));
    }
    std::vector<uint8_t> bytes;
    uint8_t buffer[1 << 16];
    size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, file)) > 0) {
        bytes.insert(bytes.end(), buffer, buffer + n);
    }
    std::fclose(file);
    const std::string unreadable = path + " is not a readable PGM or PNG image: ";
    if (bytes.size() < 2 || bytes[0] != 'P' || bytes[1] != '5') {
        fail(unreadable + "hdl/sim.sh reads binary 8-bit PGM (P5) only");
    }
    size_t at = 2;
    auto is_space = [](uint8_t c) {
        return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f';
    };
    auto next_number = [&](const char* what) -> unsigned long {
        for (;;) {
            while (at < bytes.size() && is_space(bytes[at])) ++at;
            if (at < bytes.size() && bytes[at] == '#') {
                while (at < bytes.size() && bytes[at] != '\n') ++at;
                continue;
            }
            break;
        }
        if (at >= bytes.size() || bytes[at] < '0' || bytes[at] > '9') {
            fail(unreadable + "bad " + what + " in the PGM header");
        }
        unsigned long value = 0;
        while (at < bytes.size() && bytes[at] >= '0' && bytes[at] <= '9') {
            value = value * 10 + (bytes[at] - '0');
            if (value > 0xFFFFFFFFul) fail(unreadable + what + " too large");
            ++at;
        }
        return value;
    };
    if (at >= bytes.size() || !is_space(bytes[at])) fail(unreadable + "bad PGM magic");
    Image image;
    image.width = static_cast<long>(next_number("width"));
    image.height = static_cast<long>(next_number("height"));
    const unsigned long maxval = next_number("maxval");
    if (at >= bytes.size() || !is_space(bytes[at])) fail(unreadable + "bad PGM header");
    ++at;  // the single whitespace before the raster
    if (maxval == 0) fail(unreadable + "Format error decoding Pnm: Image MAXVAL is zero");
    if (maxval > 255) {
        fail(path + " is L16, expected 8-bit grayscale (convert it first, e.g. to an 8-bit PGM)");
    }
    const size_t count = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
    if (bytes.size() - at < count) fail(unreadable + "failed to fill whole buffer");
    image.pixels.assign(bytes.begin() + at, bytes.begin() + at + count);
    if (maxval != 255) {
        const float factor = 255.0f / static_cast<float>(maxval);
        for (uint8_t& v : image.pixels) {
            const float scaled = std::round(static_cast<float>(v) * factor);
            v = scaled >= 255.0f ? 255 : static_cast<uint8_t>(scaled);
        }
    }
    return image;
}

// Rust's `str::parse` for integers: an optional sign, then at least one decimal digit, nothing
// else; out of range is an error. (Values up to u64::MAX, in 128 bits.)
using Wide = __int128;

std::string wide_text(Wide value) {
    if (value == 0) return "0";
    const bool negative = value < 0;
    std::string digits;
    for (Wide v = value; v != 0; v /= 10) {
        const int digit = static_cast<int>(v % 10);
        digits.insert(digits.begin(), static_cast<char>('0' + (digit < 0 ? -digit : digit)));
    }
    return negative ? "-" + digits : digits;
}

bool parse_integer(const char* text, Wide min, Wide max, Wide* out, std::string* why) {
    const char* p = text;
    bool negative = false;
    if (*p == '+' || *p == '-') {
        negative = *p == '-';
        ++p;
    }
    if (*p == '\0') {
        *why = "cannot parse integer from empty string";
        return false;
    }
    Wide magnitude = 0;
    for (; *p != '\0'; ++p) {
        if (*p < '0' || *p > '9') {
            *why = "invalid digit found in string";
            return false;
        }
        magnitude = magnitude * 10 + (*p - '0');
        if (magnitude > (static_cast<Wide>(1) << 70)) magnitude = static_cast<Wide>(1) << 70;
    }
    if (negative && min >= 0 && magnitude != 0) {
        *why = "invalid digit found in string";
        return false;
    }
    const Wide value = negative ? -magnitude : magnitude;
    if (value < min || value > max) {
        *why = std::string(text) + " is not in " + wide_text(min) + "..=" + wide_text(max);
        return false;
    }
    *out = value;
    return true;
}

Wide argument(const char* text, const char* option, Wide min, Wide max) {
    Wide value = 0;
    std::string why;
    if (!parse_integer(text, min, max, &value, &why)) {
        std::fprintf(stderr, "error: invalid value '%s' for '%s': %s\n\nFor more information, try '--help'.\n",
                     text, option, why.c_str());
        std::exit(2);
    }
    return value;
}

// xorshift64*, for the irregular streams of HDL_SIM_SEED.
struct Rng {
    uint64_t state;
    uint64_t next() {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        return state * 0x2545F4914F6CDD1Dull;
    }
    bool chance(unsigned percent) { return next() % 100 < percent; }
};

uint32_t crc32(const uint8_t* data, size_t size) {
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < size; ++i) {
        crc ^= data[i];
        for (int bit = 0; bit < 8; ++bit) crc = (crc & 1) ? (crc >> 1) ^ 0xEDB88320u : crc >> 1;
    }
    return ~crc;
}

uint32_t le32(const uint8_t* p) {
    return p[0] | (p[1] << 8) | (p[2] << 16) | (static_cast<uint32_t>(p[3]) << 24);
}
uint16_t le16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }

struct Feature {
    uint16_t x_q4;
    uint16_t y_q4;
    int32_t r;
    bool operator==(const Feature& o) const {
        return x_q4 == o.x_q4 && y_q4 == o.y_q4 && r == o.r;
    }
};

// The board with its clock, the registers' raw values, and the byte stream it has sent.
class Board {
  public:
    explicit Board(uint64_t seed) : rng_{seed ? seed : 1}, irregular_(seed != 0) {
        // With a seed, every register and memory bit starts random (no reset of the line
        // buffers or the datapath is needed: harris_detector.v); without, at zero.
        if (irregular_) {
            context_.randReset(2);
            context_.randSeed(static_cast<int>(seed & 0x7FFFFFFF));
        }
        top_ = std::make_unique<Vstereo_board>(&context_);
        // Inputs are the testbench's: all at rest (randReset randomises them too).
        top_->clk = 0;
        top_->width = 0;
        top_->height = 0;
        top_->threshold = 0;
        top_->max_features = 0;
        top_->load_counter = 0;
        top_->counter_value = 0;
        top_->frame_start = 0;
        top_->frame_t_us = 0;
        top_->pixel_valid = 0;
        top_->left_pixel = 0;
        top_->right_pixel = 0;
        top_->rst = 1;
        top_->out_ready = 1;
        for (int i = 0; i < 4; ++i) tick();
        top_->rst = 0;
        tick();
    }
    ~Board() { top_->final(); }

    void set_registers(long width, long height, int32_t threshold, uint64_t max_features) {
        // A value the register cannot hold is written as 0, which is out of range too: the
        // board then reports the same register as out of range.
        top_->width = width <= kMaxSize ? static_cast<uint32_t>(width) : 0;
        top_->height = height <= kMaxSize ? static_cast<uint32_t>(height) : 0;
        top_->threshold = static_cast<uint32_t>(threshold);
        top_->max_features = max_features <= kMaxFeaturesLimit ? static_cast<uint32_t>(max_features) : 0;
    }

    void load_counter(uint32_t value) {
        top_->load_counter = 1;
        top_->counter_value = value;
        tick();
        top_->load_counter = 0;
    }

    // Starts a frame; returns the board's config_error bits for its registers.
    unsigned start_frame(uint64_t t_us) {
        while (!top_->ready) tick();
        top_->frame_start = 1;
        top_->frame_t_us = t_us;
        tick();
        top_->frame_start = 0;
        tick();
        return top_->config_error;
    }

    // Streams the image pair, then waits until the frame's packet is out (or the frame was
    // dropped). `hold_last` keeps the last pixel back while the previous packet is still being
    // sent, so that no frame is dropped for a slow link.
    void run_frame(const Image& left, const Image& right) {
        const size_t count = left.pixels.size();
        const uint32_t dropped = top_->frames_dropped;
        for (size_t i = 0; i < count; ++i) {
            if (i + 1 == count) {
                while (top_->sending) tick();
            }
            while (irregular_ && rng_.chance(20)) tick();
            top_->pixel_valid = 1;
            top_->left_pixel = left.pixels[i];
            top_->right_pixel = right.pixels[i];
            tick();
            top_->pixel_valid = 0;
        }
        // Wait for the packet to begin (or the drop to be counted), then to end.
        uint64_t waited = 0;
        while (!top_->sending && top_->frames_dropped == dropped && waited++ < kPacketTimeout) tick();
        while (top_->sending && waited++ < kPacketTimeout) tick();
        if (waited >= kPacketTimeout) fail("hdl simulation: the board sent no packet (hang)", 3);
    }

    // Lets an erroneous frame's drop be counted.
    void settle() {
        for (int i = 0; i < 8; ++i) tick();
    }

    uint32_t frames_dropped() const { return top_->frames_dropped; }
    const std::vector<uint8_t>& stream() const { return stream_; }

  private:
    void tick() {
        // The link's side of the handshake is decided before the edge, from the outputs.
        if (irregular_) top_->out_ready = rng_.chance(70);
        const bool take = !top_->rst && top_->out_valid && top_->out_ready;
        const uint8_t byte = top_->out_byte;
        top_->clk = 0;
        top_->eval();
        top_->clk = 1;
        top_->eval();
        context_.timeInc(1);
        if (take) stream_.push_back(byte);
    }

    VerilatedContext context_;
    std::unique_ptr<Vstereo_board> top_;
    Rng rng_;
    bool irregular_;
    std::vector<uint8_t> stream_;
};

// The board's register check (harris_detector.v's config_error bits) as stereonav words it.
[[noreturn]] void config_failure(const std::string& path, unsigned bits, long width, long height,
                                 uint64_t max_features) {
    const std::string range = std::to_string(kMinSize) + "..=" + std::to_string(kMaxSize);
    if (bits & 1) fail(path + ": image width " + std::to_string(width) + " is outside the board's range " + range);
    if (bits & 2) fail(path + ": image height " + std::to_string(height) + " is outside the board's range " + range);
    fail(path + ": max_features " + std::to_string(max_features) + " is outside the board's range 1..=" +
         std::to_string(kMaxFeaturesLimit));
}

// Splits one packet from the front of `stream` (checking everything the ICD fixes).
size_t parse_packet(const std::vector<uint8_t>& stream, size_t at, std::vector<Feature>* left,
                    std::vector<Feature>* right, uint8_t* flags) {
    auto bad = [](const char* what) { fail(std::string("hdl simulation: bad packet: ") + what, 3); };
    if (stream.size() - at < kHeaderBytes + kCrcBytes) bad("too short");
    const uint8_t* p = stream.data() + at;
    if (p[0] != 0x5A || p[1] != 0xA5 || p[2] != 0x3C || p[3] != 0xC3) bad("sync");
    if (p[4] != 1) bad("version");
    if (p[5] & ~3u) bad("flags");
    if (le16(p + 10) != 0) bad("reserved");
    const size_t n_left = le16(p + 6), n_right = le16(p + 8);
    if (n_left > kMaxFeaturesLimit || n_right > kMaxFeaturesLimit) bad("counts");
    const size_t size = kHeaderBytes + kFeatureBytes * (n_left + n_right) + kCrcBytes;
    if (stream.size() - at < size) bad("truncated");
    if (crc32(p + 4, size - 4 - kCrcBytes) != le32(p + size - kCrcBytes)) bad("CRC");
    *flags = p[5];
    left->clear();
    right->clear();
    for (size_t i = 0; i < n_left + n_right; ++i) {
        const uint8_t* f = p + kHeaderBytes + kFeatureBytes * i;
        const Feature feature{le16(f), le16(f + 2), static_cast<int32_t>(le32(f + 4))};
        (i < n_left ? left : right)->push_back(feature);
    }
    return size;
}

uint64_t seed_from_env() {
    const char* text = std::getenv("HDL_SIM_SEED");
    return text != nullptr ? std::strtoull(text, nullptr, 10) : 0;
}

int harris(int argc, char** argv) {
    if (argc != 5 && argc != 6) {
        std::fprintf(stderr, "usage: bash hdl/sim.sh IMAGE.pgm THRESHOLD MAX_FEATURES\n");
        return 2;
    }
    // The image's name in messages (argv[5], when sim.sh converted the image to a PGM first).
    const std::string path = argc == 6 ? argv[5] : argv[2];
    const int32_t threshold =
        static_cast<int32_t>(argument(argv[3], "--threshold <THRESHOLD>", INT32_MIN, INT32_MAX));
    const uint64_t max_features =
        static_cast<uint64_t>(argument(argv[4], "--max-features <MAX_FEATURES>", 0, UINT64_MAX));
    const Image image = read_pgm(argv[2], path);

    Board board(seed_from_env());
    board.set_registers(image.width, image.height, threshold, max_features);
    if (const unsigned bits = board.start_frame(0)) {
        config_failure(path, bits, image.width, image.height, max_features);
    }
    board.run_frame(image, image);

    std::vector<Feature> left, right;
    uint8_t flags = 0;
    const size_t size = parse_packet(board.stream(), 0, &left, &right, &flags);
    if (size != board.stream().size()) fail("hdl simulation: bytes after the packet", 3);
    if (!(left == right) || (flags & 1) != (flags >> 1)) {
        fail("hdl simulation: the two cameras disagree on the same image", 3);
    }
    std::string out = "x_q4,y_q4,r\n";
    char line[64];
    for (const Feature& f : left) {
        std::snprintf(line, sizeof line, "%u,%u,%d\n", f.x_q4, f.y_q4, f.r);
        out += line;
    }
    std::fwrite(out.data(), 1, out.size(), stdout);
    return 0;
}

int packet(int argc, char** argv) {
    if (argc < 10 || (argc - 8) % 2 != 0) {
        std::fprintf(stderr,
                     "usage: board_tb packet OUT THRESHOLD MAX_FEATURES T0_US PERIOD_US FIRST_FRAME LEFT RIGHT [LEFT RIGHT ...]\n");
        return 2;
    }
    const std::string out = argv[2];
    const int32_t threshold =
        static_cast<int32_t>(argument(argv[3], "--threshold <THRESHOLD>", INT32_MIN, INT32_MAX));
    const uint64_t max_features =
        static_cast<uint64_t>(argument(argv[4], "--max-features <MAX_FEATURES>", 0, UINT64_MAX));
    const uint64_t t0_us = static_cast<uint64_t>(argument(argv[5], "--t0-us <T0_US>", 0, UINT64_MAX));
    const uint64_t period_us =
        static_cast<uint64_t>(argument(argv[6], "--period-us <PERIOD_US>", 0, UINT64_MAX));
    const uint32_t first_frame =
        static_cast<uint32_t>(argument(argv[7], "--first-frame <FIRST_FRAME>", 0, UINT32_MAX));

    Board board(seed_from_env());
    board.load_counter(first_frame);
    for (int i = 8; i < argc; i += 2) {
        const Image left = read_pgm(argv[i], argv[i]);
        const Image right = read_pgm(argv[i + 1], argv[i + 1]);
        if (left.width != right.width || left.height != right.height) {
            fail(std::string(argv[i + 1]) + ": the pair's images differ in size");
        }
        board.set_registers(left.width, left.height, threshold, max_features);
        const uint64_t pair = static_cast<uint64_t>((i - 8) / 2);
        // stereonav's saturating t0 + period * i.
        const unsigned __int128 t = static_cast<unsigned __int128>(period_us) * pair + t0_us;
        const uint64_t t_us = t > UINT64_MAX ? UINT64_MAX : static_cast<uint64_t>(t);
        if (const unsigned bits = board.start_frame(t_us)) {
            config_failure(argv[i], bits, left.width, left.height, max_features);
        }
        board.run_frame(left, right);
        if (board.frames_dropped() != 0) fail("hdl simulation: a frame was dropped", 3);
    }
    FILE* file = std::fopen(out.c_str(), "wb");
    if (file == nullptr) fail("cannot write " + out + ": " + std::strerror(errno));
    const std::vector<uint8_t>& bytes = board.stream();
    if (std::fwrite(bytes.data(), 1, bytes.size(), file) != bytes.size() || std::fclose(file) != 0) {
        fail("cannot write " + out);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc >= 2 && std::strcmp(argv[1], "harris") == 0) return harris(argc, argv);
    if (argc >= 2 && std::strcmp(argv[1], "packet") == 0) return packet(argc, argv);
    std::fprintf(stderr, "usage: board_tb harris IMAGE THRESHOLD MAX_FEATURES | board_tb packet OUT ...\n");
    return 2;
}
