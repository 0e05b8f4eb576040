"""Service requests' memory is freed after each request (issue 47 item 5): the cell's Fast DDS profile gives
every service's request reader the DYNAMIC history memory policy, which rmw_fastrtps applies only with
RMW_FASTRTPS_USE_QOS_FROM_XML=1 (set with the profile); its other readers and writers keep rmw_fastrtps's
own choices. The memory itself: bench/bench_request_memory.py (docs/perception.md, "Input bounds")."""
import xml.etree.ElementTree as ET

import pytest

from defgg_ros.ros import transport

pytestmark = pytest.mark.unit
NS = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def test_the_profile_frees_service_requests_and_keeps_rmw_defaults_elsewhere():
    root = ET.parse(transport.FASTDDS_PROFILE).getroot()
    assert root.find("f:data_reader[@profile_name='service']/f:historyMemoryPolicy", NS).text == "DYNAMIC"
    reader = root.find("f:data_reader[@is_default_profile='true']", NS)
    writer = root.find("f:data_writer[@is_default_profile='true']", NS)
    assert reader.find("f:historyMemoryPolicy", NS).text == "PREALLOCATED_WITH_REALLOC"
    assert writer.find("f:historyMemoryPolicy", NS).text == "PREALLOCATED_WITH_REALLOC"
    assert writer.find("f:qos/f:publishMode/f:kind", NS).text == "ASYNCHRONOUS"
    # rmw_fastrtps's own choice, which it does not apply when the file chooses: left AUTO, plain types' writers
    # (/clock) failed under load with "cannot publish data"
    for endpoint in (reader, writer, root.find("f:data_reader[@profile_name='service']", NS)):
        assert endpoint.find("f:qos/f:data_sharing/f:kind", NS).text == "OFF"


def test_qos_from_xml_is_set_only_by_the_call_that_chooses_the_profile(monkeypatch):
    monkeypatch.delenv(transport.FASTDDS_PROFILE_VARIABLE, raising=False)
    monkeypatch.delenv(transport.QOS_FROM_XML_VARIABLE, raising=False)
    transport.use_large_message_transport()
    assert transport.os.environ[transport.FASTDDS_PROFILE_VARIABLE] == str(transport.FASTDDS_PROFILE)
    assert transport.os.environ[transport.QOS_FROM_XML_VARIABLE] == "1"
    # A profile variable set before (the user's own file, or ours set by a test that removes it again after):
    # the variable is left alone, so it never outlives the profile it needs.
    for profile in ("/somewhere/their_own_profile.xml", str(transport.FASTDDS_PROFILE)):
        monkeypatch.setenv(transport.FASTDDS_PROFILE_VARIABLE, profile)
        monkeypatch.delenv(transport.QOS_FROM_XML_VARIABLE)
        transport.use_large_message_transport()
        assert transport.QOS_FROM_XML_VARIABLE not in transport.os.environ
        monkeypatch.setenv(transport.QOS_FROM_XML_VARIABLE, "0")
