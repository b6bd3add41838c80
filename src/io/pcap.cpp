// The UDP datagrams of a libpcap capture: libpcap reads the capture records; the link,
// IPv4 (with fragment reassembly) and UDP headers are parsed here, every length checked
// against the bytes captured.

#include <pcap/pcap.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <map>
#include <tuple>
#include <unordered_map>

#include "io/internal.hpp"
#include "io/sensor_log_internal.hpp"

namespace lex3d::io::detail {

namespace {

std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
std::uint32_t be32(const std::uint8_t* p) {
  return (static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
         (static_cast<std::uint32_t>(p[2]) << 8) | p[3];
}

std::string ip_text(std::uint32_t ip) {
  return std::to_string(ip >> 24) + "." + std::to_string((ip >> 16) & 255) + "." + std::to_string((ip >> 8) & 255) +
         "." + std::to_string(ip & 255);
}

constexpr std::size_t kMaxPendingSets = 4096;  // unfinished fragment sets held at once

/// The fragments of one IPv4 datagram seen so far.
struct FragmentSet {
  std::vector<std::uint8_t> bytes;                       // IP payload, grown as fragments arrive
  std::vector<std::pair<std::size_t, std::size_t>> got;  // [begin, end) byte ranges received
  std::size_t total = 0;                                 // payload size, known once the last fragment came
  bool have_last = false;
  std::size_t first_record = 0;
  std::size_t last_record = 0;

  [[nodiscard]] std::size_t covered() const {
    auto r = got;
    std::sort(r.begin(), r.end());
    std::size_t end = 0, sum = 0;
    for (const auto& [b, e] : r) {
      const std::size_t bb = std::max(b, end);
      if (e > bb) sum += e - bb;
      end = std::max(end, e);
    }
    return sum;
  }
  [[nodiscard]] bool complete() const { return have_last && covered() == total; }
};

using FragmentKey = std::tuple<std::uint32_t, std::uint32_t, std::uint16_t, std::uint8_t>;

}  // namespace

struct PcapDatagrams::Impl {
  std::string path;
  SensorLogInfo* info = nullptr;
  pcap_t* pc = nullptr;
  int link = 0;
  std::map<FragmentKey, FragmentSet> pending;
  std::vector<std::pair<FragmentKey, FragmentSet>> abandoned;
  // Per source: first and last capture record of its complete fragmented datagrams.
  std::unordered_map<std::uint32_t, std::pair<std::size_t, std::size_t>> frag_span;
  std::uint64_t captured_ns = 0;  // the current record's time
  std::size_t record = 0;
  bool ended = false;

  ~Impl() {
    if (pc != nullptr) pcap_close(pc);
  }

  /// The UDP datagram of IP payload `p` (n bytes captured; `claimed`: the IP payload size
  /// the IPv4 header announces, > n when the record is short) into `out`.
  Status udp(std::uint32_t src, std::uint32_t dst, const std::uint8_t* p, std::size_t n, std::size_t claimed,
             Datagram& out) {
    Datagram d;
    d.src_ip = src;
    d.dst_ip = dst;
    d.record = record;
    d.captured_ns = captured_ns;
    if (n < 8) {  // not even the UDP header
      d.truncated = true;
      d.claimed = claimed >= 8 ? claimed - 8 : 0;
      out = std::move(d);
      ++info->udp_datagrams;
      return {};
    }
    d.src_port = be16(p);
    d.dst_port = be16(p + 2);
    const std::uint16_t len = be16(p + 4);
    if (len < 8)
      return bad_data(msg(path, "capture record " + std::to_string(record) + ": UDP length " + std::to_string(len) +
                                    " is shorter than the UDP header"));
    d.claimed = len - 8U;
    d.truncated = len > n || claimed > n;
    d.payload.assign(p + 8, p + std::min<std::size_t>(len, n));
    out = std::move(d);
    ++info->udp_datagrams;
    return {};
  }

  /// Fragment sets left over at the end: tolerated where the capture cut them (before the
  /// source's first complete fragmented datagram or after its last one); an error in between.
  Status leftovers() {
    for (auto& kv : pending) abandoned.emplace_back(kv.first, std::move(kv.second));
    pending.clear();
    for (const auto& [key, fs] : abandoned) {
      const auto sp = frag_span.find(std::get<0>(key));
      const bool at_edge = sp == frag_span.end() || fs.last_record < sp->second.first || fs.first_record > sp->second.second;
      if (!at_edge)
        return bad_data(msg(path, "IPv4 datagram id " + std::to_string(std::get<2>(key)) + " from " +
                                      ip_text(std::get<0>(key)) + " never completes: " + std::to_string(fs.covered()) +
                                      " bytes of its fragments seen" +
                                      (fs.have_last ? " of " + std::to_string(fs.total) : std::string()) +
                                      " (capture records " + std::to_string(fs.first_record) + "-" +
                                      std::to_string(fs.last_record) + ")"));
      ++info->incomplete_datagrams;
    }
    abandoned.clear();
    return {};
  }

  /// Reads capture records until one completes a UDP datagram (true, in `out`) or the
  /// capture ends (false).
  StatusOr<bool> next(Datagram& out) {
    if (ended) return false;
    pcap_pkthdr* hdr = nullptr;
    const u_char* data = nullptr;
    for (;;) {
      const int rc = pcap_next_ex(pc, &hdr, &data);
      if (rc == -2) {  // end of the capture
        ended = true;
        Status s = leftovers();
        if (!s.ok()) return s;
        return false;
      }
      if (rc != 1)
        return bad_data(msg(path, "capture record " + std::to_string(record + 1) + ": " + printable(pcap_geterr(pc), 200) +
                                      " (damaged or truncated capture file)"));
      ++record;
      ++info->pcap_packets;
      captured_ns = hdr->ts.tv_sec >= 0 && hdr->ts.tv_usec >= 0 && hdr->ts.tv_usec < 1000000000
                        ? static_cast<std::uint64_t>(hdr->ts.tv_sec) * 1000000000ULL + static_cast<std::uint64_t>(hdr->ts.tv_usec)
                        : 0;
      const std::uint8_t* p = data;
      std::size_t n = hdr->caplen;
      const bool cut = hdr->caplen < hdr->len;
      // link layer -> IPv4
      std::uint16_t ethertype = 0x0800;
      if (link == DLT_EN10MB) {
        if (n < 14) {
          ++info->other_packets;
          continue;
        }
        ethertype = be16(p + 12);
        p += 14;
        n -= 14;
        while ((ethertype == 0x8100 || ethertype == 0x88A8) && n >= 4) {
          ethertype = be16(p + 2);
          p += 4;
          n -= 4;
        }
      } else if (link == DLT_LINUX_SLL) {
        if (n < 16) {
          ++info->other_packets;
          continue;
        }
        ethertype = be16(p + 14);
        p += 16;
        n -= 16;
      } else if (link == DLT_NULL || link == DLT_LOOP) {
        if (n < 4) {
          ++info->other_packets;
          continue;
        }
        std::uint32_t fam = 0;
        std::memcpy(&fam, p, 4);
        ethertype = (fam == 2 || fam == 0x02000000U) ? 0x0800 : 0;
        p += 4;
        n -= 4;
      } else if (n >= 1 && (p[0] >> 4) != 4) {
        ethertype = 0;  // raw IP that is not IPv4
      }
      if (ethertype != 0x0800 || n < 20 || (p[0] >> 4) != 4) {
        ++info->other_packets;
        continue;
      }
      const std::size_t ihl = static_cast<std::size_t>(p[0] & 15U) * 4;
      const std::size_t total = be16(p + 2);
      const std::uint8_t proto = p[9];
      if (ihl > n) {
        ++info->other_packets;
        continue;
      }
      if (ihl < 20 || total < ihl)
        return bad_data(msg(path, "capture record " + std::to_string(record) + ": malformed IPv4 header (header " +
                                      std::to_string(ihl) + " bytes, total length " + std::to_string(total) + ")"));
      if (proto != 17) {
        ++info->other_packets;
        continue;
      }
      const bool short_record = total > n;  // cut by the snap length, or a damaged record
      const std::uint32_t src = be32(p + 12);
      const std::uint32_t dst = be32(p + 16);
      const std::uint16_t frag = be16(p + 6);
      const bool more = (frag & 0x2000U) != 0;
      const std::size_t offset = static_cast<std::size_t>(frag & 0x1FFFU) * 8;
      const std::uint8_t* body = p + ihl;
      const std::size_t body_n = (short_record ? n : total) - ihl;
      if (!more && offset == 0) {
        Status s = udp(src, dst, body, body_n, total - ihl, out);
        if (!s.ok()) return s;
        return true;
      }
      // a fragment
      if (short_record)
        return bad_data(msg(path, "capture record " + std::to_string(record) + ": IPv4 fragment of " + std::to_string(total) +
                                      " bytes has only " + std::to_string(n) + " captured" +
                                      (cut ? " (cut by the capture's snap length)" : "") + " (truncated packet)"));
      if (offset + body_n > 65535)
        return bad_data(msg(path, "capture record " + std::to_string(record) + ": IPv4 fragment reaches past 65,535 bytes"));
      const FragmentKey key{src, dst, be16(p + 4), proto};
      auto it = pending.find(key);
      if (it == pending.end()) {
        if (pending.size() >= kMaxPendingSets)
          return bad_data(msg(path, "capture record " + std::to_string(record) + ": more than " +
                                        std::to_string(kMaxPendingSets) + " IPv4 datagrams with fragments outstanding"));
        it = pending.emplace(key, FragmentSet{}).first;
        it->second.first_record = record;
      }
      // A fragment at an offset already held starts another datagram with the same id (the
      // 16-bit id wrapped, or the first one lost its other fragments): the old set is abandoned.
      bool repeated = false;
      for (const auto& g : it->second.got) repeated = repeated || g.first == offset;
      if (repeated) {
        abandoned.emplace_back(key, std::move(it->second));
        it->second = FragmentSet{};
        it->second.first_record = record;
      }
      FragmentSet& fs = it->second;
      if (fs.bytes.size() < offset + body_n) fs.bytes.resize(offset + body_n);
      std::memcpy(fs.bytes.data() + offset, body, body_n);
      fs.got.emplace_back(offset, offset + body_n);
      fs.last_record = record;
      if (!more) {
        fs.have_last = true;
        fs.total = offset + body_n;
      }
      if (fs.have_last && fs.bytes.size() > fs.total)
        return bad_data(msg(path, "capture record " + std::to_string(record) + ": IPv4 fragments of datagram id " +
                                      std::to_string(std::get<2>(key)) + " reach past its last fragment"));
      if (fs.complete()) {
        Status s = udp(src, dst, fs.bytes.data(), fs.total, fs.total, out);
        if (!s.ok()) return s;
        ++info->fragmented_datagrams;
        auto [sp, inserted] = frag_span.try_emplace(src, fs.first_record, fs.last_record);
        if (!inserted) {
          sp->second.first = std::min(sp->second.first, fs.first_record);
          sp->second.second = std::max(sp->second.second, fs.last_record);
        }
        pending.erase(it);
        return true;
      }
    }
  }
};

PcapDatagrams::PcapDatagrams() : impl_(std::make_unique<Impl>()) {}
PcapDatagrams::~PcapDatagrams() = default;

Status PcapDatagrams::open(const std::string& path, SensorLogInfo& info) {
  impl_ = std::make_unique<Impl>();
  impl_->path = path;
  impl_->info = &info;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return io_error(msg(path, std::string("cannot open: ") + std::strerror(errno)));
  if (S_ISDIR(st.st_mode)) return io_error(msg(path, "is a directory"));
  char errbuf[PCAP_ERRBUF_SIZE] = {0};
  // (record times in nanoseconds whatever the file's own precision)
  impl_->pc = pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, errbuf);
  if (impl_->pc == nullptr) return bad_data(msg(path, std::string("not a readable pcap capture: ") + printable(errbuf, 200)));
  const int link = pcap_datalink(impl_->pc);
  if (link != DLT_EN10MB && link != DLT_LINUX_SLL && link != DLT_RAW && link != DLT_NULL && link != DLT_LOOP
#ifdef DLT_IPV4
      && link != DLT_IPV4
#endif
  )
    return bad_data(msg(path, "capture link type " + std::to_string(link) +
                                  " is not supported (Ethernet, Linux cooked, raw IP or loopback)"));
  impl_->link = link;
  return {};
}

StatusOr<bool> PcapDatagrams::next(Datagram& out) {
  if (impl_->pc == nullptr) return false;
  return impl_->next(out);
}

Status read_udp_datagrams(const std::string& path, std::vector<Datagram>& out, SensorLogInfo& info) {
  PcapDatagrams capture;
  Status s = capture.open(path, info);
  if (!s.ok()) return s;
  for (;;) {
    Datagram d;
    auto more = capture.next(d);
    if (!more.ok()) return more.status();
    if (!more.value()) return {};
    out.push_back(std::move(d));
  }
}

}  // namespace lex3d::io::detail
