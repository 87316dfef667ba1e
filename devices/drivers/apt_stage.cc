// Thorlabs APT z stage: connect, home, absolute moves with timeout and settle (see apt_stage.h).
#include "devices/drivers/apt_stage.h"

#include <algorithm>
#include <cmath>
#include <thread>

namespace inspection {
namespace {

using Clock = std::chrono::steady_clock;

Clock::time_point After(double ms) {
  return Clock::now() + std::chrono::microseconds(static_cast<int64_t>(ms * 1000.0));
}

}  // namespace

StatusOr<AptStageType> LookupAptStageType(const std::string& name) {
  // Z8 series: 512 counts/rev motor encoder x 67.49:1 gearhead, 1 mm lead screw.
  // MTS25/MTS50-Z8: 512 x 67:1, 1 mm lead screw.
  static const AptStageType kTypes[] = {
      {"Z806", 34554.96, 6.0},     {"Z812", 34554.96, 12.0},    {"Z825", 34554.96, 25.0},
      {"MTS25-Z8", 34304.0, 25.0}, {"MTS50-Z8", 34304.0, 50.0},
  };
  std::string known;
  for (const AptStageType& t : kTypes) {
    if (t.name == name) return t;
    known += (known.empty() ? "" : ", ") + t.name;
  }
  return Status::NotFound("unknown stage type '" + name + "' (known: " + known + ")");
}

Status AptStageOptions::Validate() const {
  StatusOr<AptStageType> type = LookupAptStageType(stage_type);
  if (!type.ok()) return Status::InvalidArgument("stage_type: " + type.status().message());
  if (counts_per_mm < 0.0) return Status::InvalidArgument("counts_per_mm must be >= 0 (0 = from stage_type)");
  if (!(min_z_um < max_z_um)) return Status::InvalidArgument("min_z_um must be < max_z_um");
  if (min_z_um < 0.0 || max_z_um > type->travel_mm * 1000.0) {
    return Status::InvalidArgument("min_z_um/max_z_um must lie within the " + stage_type + " travel 0.." +
                                   std::to_string(static_cast<int>(type->travel_mm * 1000.0)) + " µm");
  }
  if (!(move_timeout_ms > 0.0)) return Status::InvalidArgument("move_timeout_ms must be > 0");
  if (!(home_timeout_ms > 0.0)) return Status::InvalidArgument("home_timeout_ms must be > 0");
  if (!(settle_ms >= 0.0)) return Status::InvalidArgument("settle_ms must be >= 0");
  if (line.baud <= 0) return Status::InvalidArgument("baud must be > 0");
  return Status::Ok();
}

AptStage::AptStage(AptStageOptions options, UsbTransportFactory open_transport)
    : options_(std::move(options)), open_transport_(std::move(open_transport)) {
  StatusOr<AptStageType> type = LookupAptStageType(options_.stage_type);
  counts_per_mm_ = options_.counts_per_mm > 0.0 ? options_.counts_per_mm : (type.ok() ? type->counts_per_mm : 0.0);
  last_error_ = "not connected yet";
  published_.Set(BuildInfo());
}

AptStage::~AptStage() = default;

int32_t AptStage::CountsFromUm(double z_um) const {
  return static_cast<int32_t>(std::lround(z_um * counts_per_mm_ / 1000.0));
}

double AptStage::UmFromCounts(int32_t counts) const { return counts * 1000.0 / counts_per_mm_; }

DeviceInfo AptStage::BuildInfo() const {
  DeviceInfo d;
  d.role = "stage";
  d.driver = "apt-usb";
  d.model = hw_info_.model.empty() ? options_.stage_type : hw_info_.model + " + " + options_.stage_type;
  d.serial = hw_info_.serial_number ? std::to_string(hw_info_.serial_number) : (transport_ ? transport_->serial() : "");
  d.connected = connected_;
  d.detail =
      connected_ ? (transport_ ? transport_->description() : "") + (homed_ ? ", homed" : ", not homed") : last_error_;
  return d;
}

Status AptStage::Fail(Status s) {
  if (s.code() == StatusCode::kUnavailable) {
    connected_ = false;
    last_error_ = s.message();
  }
  return s;
}

Status AptStage::CheckConnected() const {
  if (connected_) return Status::Ok();
  return Status::Unavailable("stage (apt-usb) is not connected: " + last_error_);
}

Status AptStage::Connect() {
  Republish publish{this};
  connected_ = false;
  serial_.reset();
  transport_.reset();
  INSPECT_RETURN_IF_ERROR(options_.Validate());
  StatusOr<std::unique_ptr<UsbTransport>> t = open_transport_();
  if (!t.ok()) {
    last_error_ = t.status().message();
    return Status::Unavailable("stage (apt-usb): " + t.status().message());
  }
  transport_ = std::move(t).value();
  serial_ = std::make_unique<FtdiSerial>(transport_.get());
  auto fail = [this](const Status& s) {
    last_error_ = s.message();
    return Status(s.code() == StatusCode::kDeadlineExceeded ? StatusCode::kUnavailable : s.code(),
                  "stage (apt-usb) " + transport_->description() + ": " + s.message());
  };
  if (Status s = serial_->Configure(options_.line); !s.ok()) return fail(s);
  if (Status s = Send(apt::NoFlashProgramming()); !s.ok()) return fail(s);
  if (Status s = Send(apt::ReqHwInfo()); !s.ok()) return fail(s);
  StatusOr<apt::Message> info = WaitFor(apt::kHwGetInfo, options_.line.control_timeout_ms, "HW_GET_INFO");
  if (!info.ok()) return fail(info.status());
  StatusOr<apt::HwInfo> parsed = apt::ParseHwInfo(*info);
  if (!parsed.ok()) return fail(parsed.status());
  hw_info_ = *parsed;
  if (Status s = Send(apt::EnableChannel(true)); !s.ok()) return fail(s);
  if (options_.identify_on_connect) {
    if (Status s = Send(apt::Identify()); !s.ok()) return fail(s);
  }
  connected_ = true;
  last_error_.clear();
  if (options_.home_on_connect) return Home();
  return Status::Ok();
}

Status AptStage::Send(const apt::Message& m) {
  return serial_->Write(apt::Encode(m), options_.line.control_timeout_ms);
}

StatusOr<apt::Message> AptStage::ReadMessage(Clock::time_point deadline) {
  INSPECT_ASSIGN_OR_RETURN(std::vector<uint8_t> header, serial_->Read(apt::kHeaderBytes, deadline));
  int length = 0;
  apt::Message m = apt::DecodeHeader(header.data(), &length);
  if (length > 0) {
    // The data packet follows the header immediately; give it at least the control timeout.
    const Clock::time_point data_deadline = std::max(deadline, After(options_.line.control_timeout_ms));
    INSPECT_ASSIGN_OR_RETURN(m.data, serial_->Read(static_cast<size_t>(length), data_deadline));
  }
  return m;
}

StatusOr<apt::Message> AptStage::WaitFor(uint16_t id, double timeout_ms, const std::string& what) {
  const Clock::time_point deadline = After(timeout_ms);
  for (;;) {
    StatusOr<apt::Message> m = ReadMessage(deadline);
    if (!m.ok()) {
      if (m.status().code() == StatusCode::kDeadlineExceeded) {
        return Status::DeadlineExceeded(what + " not received within " + std::to_string(static_cast<int>(timeout_ms)) +
                                        " ms");
      }
      return m.status();
    }
    if (m->id == apt::kHwResponse || m->id == apt::kHwRichResponse) {
      return Status::Aborted("waiting for " + what + ": " + apt::DescribeControllerError(*m));
    }
    if (m->id == apt::kMotMoveCompleted || m->id == apt::kMotMoveHomed || m->id == apt::kMotMoveStopped ||
        m->id == apt::kMotGetDcStatusUpdate) {
      // USB controllers stop sending status updates unless the host acknowledges them.
      INSPECT_RETURN_IF_ERROR(Send(apt::AckDcStatusUpdate()));
    }
    if (m->id == id) return m;
  }
}

Status AptStage::Home() {
  Republish publish{this};
  INSPECT_RETURN_IF_ERROR(CheckConnected());
  INSPECT_RETURN_IF_ERROR(Fail(Send(apt::MoveHome())));
  StatusOr<apt::Message> homed = WaitFor(apt::kMotMoveHomed, options_.home_timeout_ms, "MOVE_HOMED");
  if (!homed.ok()) {
    if (homed.status().code() == StatusCode::kDeadlineExceeded) Send(apt::MoveStop(false)).IgnoreError();
    return Fail(homed.status().WithContext("stage home"));
  }
  homed_ = true;
  last_position_counts_ = 0;
  return Status::Ok();
}

Status AptStage::MoveTo(double z_um) {
  Republish publish{this};
  if (!std::isfinite(z_um) || z_um < options_.min_z_um || z_um > options_.max_z_um) {
    return Status::OutOfRange("stage z " + std::to_string(z_um) + " µm outside travel limits [" +
                              std::to_string(options_.min_z_um) + ", " + std::to_string(options_.max_z_um) + "] µm");
  }
  INSPECT_RETURN_IF_ERROR(CheckConnected());
  const int32_t target = CountsFromUm(z_um);
  INSPECT_RETURN_IF_ERROR(Fail(Send(apt::MoveAbsolute(target))));
  StatusOr<apt::Message> done = WaitFor(apt::kMotMoveCompleted, options_.move_timeout_ms, "MOVE_COMPLETED");
  if (!done.ok()) {
    if (done.status().code() == StatusCode::kDeadlineExceeded) Send(apt::MoveStop(false)).IgnoreError();
    return Fail(done.status().WithContext("stage move to " + std::to_string(z_um) + " µm"));
  }
  StatusOr<apt::MotorStatus> st = apt::ParseMotorStatus(*done);
  last_position_counts_ = st.ok() ? st->position_counts : target;
  // Mechanical settling before the camera may expose (thesis 6: the stage must be at rest).
  if (options_.settle_ms > 0)
    std::this_thread::sleep_for(std::chrono::microseconds(static_cast<int64_t>(options_.settle_ms * 1000)));
  return Status::Ok();
}

StatusOr<double> AptStage::position_um() {
  Republish publish{this};
  INSPECT_RETURN_IF_ERROR(CheckConnected());
  INSPECT_RETURN_IF_ERROR(Fail(Send(apt::ReqPosCounter())));
  StatusOr<apt::Message> reply = WaitFor(apt::kMotGetPosCounter, options_.line.control_timeout_ms, "GET_POSCOUNTER");
  if (!reply.ok()) return Fail(reply.status());
  INSPECT_ASSIGN_OR_RETURN(int32_t counts, apt::ParsePosCounter(*reply));
  last_position_counts_ = counts;
  return UmFromCounts(counts);
}

StatusOr<apt::MotorStatus> AptStage::QueryStatus() {
  Republish publish{this};
  INSPECT_RETURN_IF_ERROR(CheckConnected());
  INSPECT_RETURN_IF_ERROR(Fail(Send(apt::ReqDcStatusUpdate())));
  StatusOr<apt::Message> reply =
      WaitFor(apt::kMotGetDcStatusUpdate, options_.line.control_timeout_ms, "GET_DCSTATUSUPDATE");
  if (!reply.ok()) return Fail(reply.status());
  INSPECT_ASSIGN_OR_RETURN(apt::MotorStatus st, apt::ParseMotorStatus(*reply));
  homed_ = homed_ || (st.status_bits & apt::kStatusHomed) != 0;
  last_position_counts_ = st.position_counts;
  return st;
}

}  // namespace inspection
