// The package's generated messages and services, made includable next to the core.
//
// The core has view_selection::NextViewSet (a std::vector<ViewId>) and view_selection::CompletedView
// (a struct); the generated message headers define typedefs of the same names in the same
// namespace. Included through this header, the two message typedefs are named NextViewSetMsg and
// CompletedViewMsg instead (the templates NextViewSet_ / CompletedView_, the Ptr typedefs and the
// wire format are unchanged). Include this header before any other header that pulls these
// messages in, in every C++ file that uses both the core and the messages.
#pragma once

#ifdef NextViewSet
#error "view_selection/ros/messages.h: NextViewSet is already a macro"
#endif
#define NextViewSet NextViewSetMsg
#define CompletedView CompletedViewMsg
#include <view_selection/CompletedView.h>
#include <view_selection/NextViewSet.h>
#undef NextViewSet
#undef CompletedView

#include <view_selection/Export.h>
#include <view_selection/GetNextViews.h>
#include <view_selection/GetSelection.h>
#include <view_selection/InputStatistics.h>
#include <view_selection/KeyframeInfo.h>
#include <view_selection/ViewPair.h>
#include <view_selection/ViewSelection.h>
